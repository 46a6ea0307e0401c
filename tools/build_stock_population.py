"""Rebuild cpapfit/cushion/data/stock_population.npz: the stock cushion family's population
(`cpapfit.cushion.population.drawn`: 200 faces of the shipped ICT model, the sizing gauge's measure
and the seal curve's depths on each), drawn again from the shipped model and template.

Usage (needs the project venv; no ../shared: it reads the shipped model):
    python tools/build_stock_population.py
"""

from pathlib import Path

from cpapfit.cushion.population import FILE, population_bytes
from cpapfit.io.write import write_bytes

if __name__ == "__main__":
    write_bytes(Path(__file__).resolve().parents[1] / "cpapfit" / "cushion" / "data" / FILE, population_bytes())
