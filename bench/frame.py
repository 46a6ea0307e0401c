"""The mask's frame on synthetic subjects and the shared real scans, both masks: the connector's cone
measured on slices of the written frame.stl (re-read as float32), the vent flow against its target,
the dead space, the cushion in the frame, and the frame's build time.

Usage: .venv/bin/python bench/frame.py [--seeds 1 2 3 4]
"""

import argparse
import io
import platform
import time
from pathlib import Path

import numpy as np
import trimesh

from cpapfit import __version__
from cpapfit.export import check_closed, stl_bytes
from cpapfit.frame import CONE_MM, build_frame, cone_diameter_mm
from cpapfit.io import load_scan
from cpapfit.io.phantom import write_phantom
from cpapfit.metrics import sliced_diameters
from cpapfit.pipeline import design, place_template
from cpapfit.synthetic import make_phantom
from cpapfit.vents import TARGET_CMH2O, TARGET_L_MIN

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
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4])
    args = parser.parse_args()
    import tempfile
    print(f"cpapfit {__version__}, {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print("| scan | mask | cone worst (mm) | vent worst error | dead space (ml) | interference (mm3) | airway closed | frame build (s) |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, scan in scans(args.seeds, Path(tmp)):
            placement = place_template(scan)
            for mask in ("nasal", "oronasal"):
                d = design(scan, mask, placement=placement, stock=None)
                start = time.perf_counter()
                frame = build_frame(d.cushion, d.solid)
                check_closed(frame.mesh, "frame")
                built = time.perf_counter() - start
                stl = trimesh.load(io.BytesIO(stl_bytes(d.frame.mesh)), file_type="stl")
                cone = np.abs(sliced_diameters(stl, d.frame.port_tip, d.frame.port_axis, FROM_TIP) - cone_diameter_mm(FROM_TIP)).max()
                vent = np.abs(d.frame.vents.flow_l_min(TARGET_CMH2O) / np.array(TARGET_L_MIN) - 1).max()
                fit = d.frame.assembly
                print(f"| {name} | {mask} | {cone:.4f} | {vent:.3f} | {d.dead_space_ml:.1f} | {fit['interference_mm3']:.4f} | "
                      f"{fit['airway_closed']} | {built:.2f} |", flush=True)


if __name__ == "__main__":
    main()
