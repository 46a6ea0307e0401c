"""Rebuild the stock cushion family's shipped data in cpapfit/cushion/data/: stock_population.npz
(`cpapfit.cushion.population.drawn`: 200 faces of the shipped ICT model, the sizing gauge's measure
and the seal curve's depths on each), drawn again from the shipped model and template (`tools/build_refined_template.py`), then
stock_solids.npz (`cpapfit.cushion.stock.solids_bytes`: every size's solid, made from that population).

Usage (needs the project venv; no ../shared: it reads the shipped model):
    python tools/build_stock_family.py
"""

from pathlib import Path

from cpapfit.io.write import write_bytes

if __name__ == "__main__":
    data = Path(__file__).resolve().parents[1] / "cpapfit" / "cushion" / "data"
    from cpapfit.cushion.population import FILE, population_bytes
    write_bytes(data / FILE, population_bytes())
    from cpapfit.cushion.stock import SOLIDS_FILE, solids_bytes  # reads the population just written
    write_bytes(data / SOLIDS_FILE, solids_bytes())
