"""The mask's frame on synthetic subjects and the shared real scans, both masks: the connector's cone
measured on slices of the written frame.stl (re-read as float32), the vent flow against its target,
the dead space and the frame ring's clearance over the nose tip, the cushion in the frame, and the
frame's build time (`build_frame` and `check_closed`). A design the quality gates refuse is a row
saying why.

Usage: .venv/bin/python bench/frame.py [--seeds 1 2 3 4 5 6 7 8]
"""

import argparse
import io
import platform
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

from cpapfit import __version__
from cpapfit.errors import CpapfitError
from cpapfit.fabrication.files import check_closed, stl_bytes
from cpapfit.fabrication.frame import CONE_MM, build_frame, cone_diameter_mm, sliced_diameters
from cpapfit.io import load_scan
from cpapfit.io.phantom import write_phantom
from cpapfit.pipeline import design, place_template
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.fabrication.vents import TARGET_CMH2O, TARGET_L_MIN

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
FROM_TIP = np.linspace(0.5, CONE_MM - 0.5, 8)


def scans(seeds, work: Path):
    for seed in seeds:
        folder = work / f"phantom{seed}"
        write_phantom(make_phantom(seed), folder)
        yield f"phantom {seed}", load_scan(folder)
    for name, path in (("fran", SHARED / "fran_cyberware" / "fran.obj"), ("truedepth", SHARED / "rgbd_truedepth_mannequin")):
        if path.exists():
            yield name, load_scan(path)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6, 7, 8])
    args = parser.parse_args()
    print(f"cpapfit {__version__}, {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print("| scan | mask | cone worst (mm) | vent worst error | dead space (ml) | ring clearance (mm) | interference (mm3) | "
          "airway closed (genus) | frame build (s) |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, scan in scans(args.seeds, Path(tmp)):
            placement = place_template(scan)
            for mask in ("nasal", "oronasal"):
                try:
                    d = design(scan, mask, placement=placement, stock=None)
                except CpapfitError as refused:
                    print(f"| {name} | {mask} | refused: {refused} ||||||||", flush=True)
                    continue
                print(_row(name, mask, d), flush=True)


def _row(name: str, mask: str, d) -> str:
    """A design's row: the written frame.stl's cone, the vents, dead space, the assembly and the frame's build time."""
    start = time.perf_counter()
    check_closed(build_frame(d.cushion, d.solid).mesh, "frame")
    built = time.perf_counter() - start
    stl = trimesh.load(io.BytesIO(stl_bytes(d.frame.mesh)), file_type="stl")
    cone = np.abs(sliced_diameters(stl, d.frame.port_tip, d.frame.port_axis, FROM_TIP) - cone_diameter_mm(FROM_TIP)).max()
    vent = np.abs(d.frame.vents.flow_l_min(TARGET_CMH2O) / np.array(TARGET_L_MIN) - 1).max()
    fit = d.frame.assembly
    return (f"| {name} | {mask} | {cone:.4f} | {vent:.3f} | {d.dead_space_ml:.1f} | {d.cushion.params.frame_clearance_mm:.1f} | "
            f"{fit['interference_mm3']:.4f} | {fit['airway_closed']} ({fit['joined_genus']}) | {built:.2f} |")

if __name__ == "__main__":
    main()
