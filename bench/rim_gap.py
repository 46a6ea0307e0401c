"""The fit before compression: the cushion rim's gap to the scan where the scan has data
(`Design.rim`: to the skin under the flange, a quadric through the scan within 4 mm), on synthetic subjects
against both the scan and the subject's true skin, and the scan's own noise floor along the same
rim: how far the true skin under the rim lies from the scan, measured the same way (a rim exactly
on the skin would show that gap). Last column: the rim's largest gap to the single closest scan
sample, and to the median of seven ray hits on the scan's triangles over a 1 mm disc along the
face's normal (the measure before the quadric), for comparison. Shared real scans: rim to scan only.

Usage: .venv/bin/python bench/rim_gap.py [--seeds 8]   (prints a Markdown table)
"""

import argparse
import platform
import tempfile
from pathlib import Path

import numpy as np
import trimesh

from cpapfit.cushion.nurbs import CushionParams, design_cushion
from cpapfit.evaluation.gap import rim_gap
from cpapfit.evaluation.rim import skin_under
from cpapfit.io import load_scan
from cpapfit.io.phantom import write_phantom
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.cushion.generic import NOSE_TIP
from cpapfit.pipeline import design, face_for

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
SAMPLES = 256  # rim samples, as `pipeline.design` measures them


def rim_points(scan, d) -> tuple[np.ndarray, trimesh.Trimesh]:
    """(SAMPLES, 3) the neutral cushion's rim (before pre-load) and the scan surface, as in `design`."""
    face = face_for(scan, d.alignment, d.registration)
    neutral = design_cushion(d.contact, face.axis, face.up, d.registration.vertices[NOSE_TIP], CushionParams())
    return neutral.grid(SAMPLES, 2)[:, 0], face.scan


def closest(surface: trimesh.Trimesh, rim: np.ndarray) -> np.ndarray:
    """(K,) mm from each rim point to its closest point on the scan surface."""
    return trimesh.proximity.closest_point(surface, rim)[1]


def rays(surface: trimesh.Trimesh, rim: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(K,) mm from each rim point to the median of seven ray hits on the scan over a 1 mm disc."""
    return np.abs(skin_under(rim, surface, normals, 10.0))


def stats(gap: np.ndarray) -> str:
    return f"{np.median(gap):.3f} | {gap.max():.3f}"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=8)
    seeds = ap.parse_args().seeds
    print(f"machine: {platform.machine()}, Python {platform.python_version()}; gaps in mm where the scan has data\n")
    print("| scan | mask | rim to scan: median | max | rim to true skin: median | max | true skin to scan (floor): median | max | rim to closest sample: max | rim to scan, 1 mm ray median: max |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(1, seeds + 1):
            ph = make_phantom(seed)
            write_phantom(ph, Path(tmp) / str(seed))
            scan = load_scan(Path(tmp) / str(seed))
            truth = trimesh.Trimesh(ph.surface, ph.faces, process=False)
            for mask in ("nasal", "oronasal"):
                d = design(scan, mask)
                rim, surface = rim_points(scan, d)
                covered = d.rim.covered
                on_skin, to_truth, _ = trimesh.proximity.closest_point(truth, rim)
                floor = rim_gap(on_skin, d.contact.normals_at(rim), scan, surface).gap
                print(f"| phantom {seed} | {mask} | {stats(d.rim.gap[covered])} | {stats(to_truth[covered])} | "
                      f"{stats(floor[covered])} | {closest(surface, rim)[covered].max():.3f} | "
                      f"{np.nanmax(rays(surface, rim, d.contact.normals_at(rim))[covered]):.3f} |", flush=True)
    for name in ("fran_cyberware/fran.obj", "rgbd_truedepth_mannequin"):
        if (SHARED / name).exists():
            scan = load_scan(SHARED / name)
            for mask in ("nasal", "oronasal"):
                try:
                    d = design(scan, mask)
                except Exception as exc:  # a bench row, not a crash
                    print(f"| {name.split('/')[0]} | {mask} | refused: {exc} |")
                    continue
                rim, surface = rim_points(scan, d)
                print(f"| {name.split('/')[0]} | {mask} | {stats(d.rim.gap[d.rim.covered])} | - | - | - | - | "
                      f"{closest(surface, rim)[d.rim.covered].max():.3f} | "
                      f"{np.nanmax(rays(surface, rim, d.contact.normals_at(rim))[d.rim.covered]):.3f} |", flush=True)


if __name__ == "__main__":
    main()
