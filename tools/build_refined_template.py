"""Rebuild the refined template shipped in cpapfit/template/data/template.npz
(`cpapfit.template.template_bytes`: MediaPipe's canonical face refined by Loop subdivision, its
contact regions and mirror pairs). The template's place on the ICT topology and the stock family's
data are made from it: run `tools/build_template_on_ict.py`, then `tools/build_stock_family.py`,
after this.

Usage (needs the project venv):
    python tools/build_refined_template.py
"""

from pathlib import Path

from cpapfit.io.write import write_bytes
from cpapfit.template import TEMPLATE_FILE, template_bytes

if __name__ == "__main__":
    write_bytes(Path(__file__).resolve().parents[1] / "cpapfit" / "template" / "data" / TEMPLATE_FILE, template_bytes())
