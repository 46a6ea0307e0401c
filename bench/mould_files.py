"""The casting mould and the mesh files a design writes, on synthetic subjects (ICT and
template-made, `cpapfit phantom`) and the shared real scans, both masks: every STL and 3MF file
re-read as a slicer reads it (float32 corners, vertices merged by position) and checked
(`fabrication.files.check_file`: each edge in two triangles, no zero-area triangle, no self-intersection),
and each mould part's draft along its pull: the undercut and under-1-degree shares of its
moulding area, and whether it meets the target (at most 5 % undercut, at least 95 % drafted by
1 degree or more). Designs without the stock comparison (it does not touch the mould).

Usage: .venv/bin/python bench/mould_files.py [--ict 5] [--template 3]
"""

import argparse
import subprocess
import tempfile
import time
from pathlib import Path

import cpapfit
from cpapfit.errors import CpapfitError
from cpapfit.fabrication.files import SolidError, checked_files
from cpapfit.io import load_scan
from cpapfit.fabrication.mould import mould
from cpapfit.pipeline import design, place_template

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
PARTS = ("mould_left", "mould_right", "mould_face", "mould_core")


def subjects(n_ict: int, n_template: int, folder: Path):
    """(name, scan path) of every subject benched."""
    for seed in range(1, n_ict + 1):
        yield f"ICT {seed}", cpapfit.phantom(seed, folder / f"ict{seed}")
    for seed in range(1, n_template + 1):
        yield f"template {seed}", cpapfit.phantom(seed, folder / f"template{seed}", population="template")
    if SHARED.is_dir():
        yield "fran", SHARED / "fran_cyberware" / "fran.obj"
        yield "TrueDepth", SHARED / "rgbd_truedepth_mannequin"


def clean_files(d) -> tuple[int, int]:
    """(files clean as re-read, files) of a design's STL and 3MF files."""
    files = [(d.solid, "cushion", kind) for kind in ("stl", "3mf")] + [(part, name, "stl") for name, part in d.mould_parts.items()]
    clean = 0
    for mesh, name, kind in files:
        try:
            checked_files(mesh, name, (kind,))
            clean += 1
        except SolidError as exc:
            print(f"  {name}.{kind}: {exc}")
    return clean, len(files)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ict", type=int, default=5)
    ap.add_argument("--template", type=int, default=3)
    args = ap.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"commit {commit}; per part: undercut % / under 1 deg % of its moulding area (* meets the target)\n")
    print("| subject | mask | files clean | left | right | face plate | core (pull) | mould (s) |")
    print("|---|---|---|---|---|---|---|---|")
    files, met, worst = [0, 0], {p: [0, 0] for p in PARTS}, {p: 0.0 for p in PARTS}
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in subjects(args.ict, args.template, Path(tmp)):
            scan = load_scan(path)
            placement = place_template(scan)
            for mask in ("nasal", "oronasal"):
                try:
                    d = design(scan, mask, placement=placement, stock=None)
                except CpapfitError as exc:
                    print(f"| {name} | {mask} | refused: {exc} | | | | | |", flush=True)
                    continue
                t0 = time.perf_counter()
                mould(d.cushion, d.solid)
                seconds = time.perf_counter() - t0
                clean, total = clean_files(d)
                files[0] += clean
                files[1] += total
                cells = []
                for part in PARTS:
                    x = d.mould_draft[part]
                    met[part][0] += x.meets_target
                    met[part][1] += 1
                    worst[part] = max(worst[part], x.undercut_fraction)
                    cells.append(f"{100 * x.undercut_fraction:.1f} / {100 * x.below_min_fraction:.1f}{' *' if x.meets_target else ''}")
                cells[-1] += f" ({d.mould_draft['mould_core'].pull_name.split('through the ')[-1]})"
                print(f"| {name} | {mask} | {clean}/{total} | {' | '.join(cells)} | {seconds:.1f} |", flush=True)
    print(f"\nfiles clean as re-read: {files[0]}/{files[1]}")
    for part in PARTS:
        print(f"{part}: meets the target on {met[part][0]}/{met[part][1]} designs; largest undercut {100 * worst[part]:.1f} %")


if __name__ == "__main__":
    main()
