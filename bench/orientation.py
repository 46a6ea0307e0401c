"""A real mesh scan turned, moved and rescaled: every orientation, unit and mesh format must give
a design, with the seal where the original orientation puts it.

Each case: the scan (default the shared fran.obj) turned by `Rotation.random(i)`, moved by up to
~0.3 m, written in m, mm or cm as OBJ (with its texture), PLY or STL (no texture), then
`pipeline.design`. Printed: the seal curve's distance to the original's (turned back, mm), the rim
gap, leak and safe window, and the headgear force set and the awake peak pressure against the
original's (how much the fit's figures move when only the scan's pose, unit or format changes),
and the design's quality flags.

Usage: .venv/bin/python bench/orientation.py [--cases 9] [--mask nasal] [--scan FILE]
(the default scan needs ../shared)
"""

import argparse
import tempfile
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from cpapfit.errors import CpapfitError
from cpapfit.io import load_scan
from cpapfit.io.units import MM_PER_UNIT
from cpapfit.pipeline import design

FRAN = Path(__file__).resolve().parents[2] / "shared" / "data" / "fran_cyberware" / "fran.obj"
UNITS = (("m", 1.0), ("mm", 1000.0), ("cm", 100.0))
FORMATS = (".obj", ".ply", ".stl")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", type=int, default=9)
    ap.add_argument("--mask", default="nasal")
    ap.add_argument("--scan", type=Path, default=FRAN, help="a mesh scan (units decided from its size)")
    args = ap.parse_args()
    original = load_scan(args.scan)
    first = design(original, args.mask)
    reference, force, peak = first.contact.curve, first.fits["custom"].force_n, first.fits["custom"].summary()["pressure_max_kpa"]
    print(f"original: headgear force {force:.2f} N, awake peak {peak:.2f} kPa")
    mesh = trimesh.load(args.scan, force="mesh", process=False)
    mesh.vertices = mesh.vertices * (MM_PER_UNIT[original.units] / 1000.0)  # metres
    print(f"original flags: {flags(first)}")
    print("| case | unit | format | seal vs original: mean | max (mm) | rim gap max (mm) | leak (L/min) | window | headgear force (N) | awake peak (kPa) | flags |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for i in range(args.cases):
        turn = Rotation.random(random_state=i).as_matrix()
        shift = np.random.default_rng(i).normal(0.0, 0.3, 3)  # metres
        (unit, per_metre), suffix = UNITS[i % 3], FORMATS[(i // 3) % 3]
        moved = mesh.copy()
        moved.vertices = (mesh.vertices @ turn.T + shift) * per_metre
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"fran{suffix}"
            moved.export(path)
            try:
                d = design(load_scan(path), args.mask)
            except CpapfitError as exc:
                print(f"| {i} | {unit} | {suffix} | refused: {exc} |", flush=True)
                continue
        back = (d.contact.curve / 1000.0 - shift) @ turn * 1000.0  # the design is in mm in the file's frame
        apart = cKDTree(back).query(reference)[0]
        custom = d.fits["custom"]
        fit = custom.summary()
        print(f"| {i} | {unit} | {suffix} | {apart.mean():.2f} | {apart.max():.2f} | {d.rim.summary()['rim_gap_max_mm']:.2f} | "
              f"{fit['leak_l_min']:.2f} | {fit['window_fraction']:.2f} | {custom.force_n:.2f} ({custom.force_n / force - 1:+.1%}) | "
              f"{fit['pressure_max_kpa']:.2f} ({fit['pressure_max_kpa'] / peak - 1:+.1%}) | {flags(d)} |", flush=True)


def flags(d) -> str:
    """The design's quality flags (the gates past their flag limits: "rescan advised"), by code."""
    return " ".join(g.code for g in d.quality.flags) or "none"


if __name__ == "__main__":
    main()
