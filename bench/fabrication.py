"""What a workshop gets, on synthetic subjects (ICT and template-made captures, `cpapfit phantom`)
and the shared real scans, both masks, each designed once (no stock comparison: it touches no file):

- files: every STL and 3MF part `design` writes (`outputs.design_files`: cushion, mould parts,
  frame, assembly) re-read from its bytes as a slicer reads it (float32 corners, vertices merged by
  position) and checked (`fabrication.files.check_file`: each edge in two triangles, no zero-area
  triangle, no self-intersection);
- the mould: each part's draft along its pull (undercut and under-1-degree shares of its moulding
  area; * meets the target: at most 5 % undercut, at least 95 % drafted by 1 degree or more) and
  the mould's build time;
- the frame: the connector's cone measured on slices of the written frame.stl along the declared
  port axis against ISO 5356-1, the vent flow against its target curve, the dead space, the frame
  ring's clearance over the nose tip, the cushion in the frame (interference, the airway closed,
  the genus of frame and cushion joined) and the frame's build time (`build_frame`, `check_closed`).

A design the quality gates refuse is a row saying why.

Usage: .venv/bin/python bench/fabrication.py [--ict 1 2 ... 8] [--template 1 2 ... 8]
"""

import argparse
import platform
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

import cpapfit
from cpapfit.errors import CpapfitError
from cpapfit.fabrication.files import check_closed, check_file, read_3mf_parts, read_stl
from cpapfit.fabrication.frame import CONE_MM, build_frame, cone_diameter_mm, sliced_diameters
from cpapfit.fabrication.mould import mould
from cpapfit.fabrication.vents import TARGET_CMH2O, TARGET_L_MIN
from cpapfit.io import load_scan
from cpapfit.outputs import design_files
from cpapfit.pipeline import design, place_template

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
PARTS = ("mould_left", "mould_right", "mould_face", "mould_core")
FROM_TIP = np.linspace(0.5, CONE_MM - 0.5, 8)


def subjects(ict: list[int], template: list[int], folder: Path):
    """(name, scan path): the ICT subjects and template-made ones of those seeds (written into
    `folder`), then fran and the TrueDepth frame where ../shared is present."""
    for seed in ict:
        yield f"ICT {seed}", cpapfit.phantom(seed, folder / f"ict{seed}")
    for seed in template:
        yield f"template {seed}", cpapfit.phantom(seed, folder / f"template{seed}", population="template")
    if SHARED.is_dir():
        yield "fran", SHARED / "fran_cyberware" / "fran.obj"
        yield "TrueDepth", SHARED / "rgbd_truedepth_mannequin"


def reread(files: dict[str, bytes]) -> tuple[int, int]:
    """(parts clean as re-read, parts) of every STL and 3MF file among a design's `files`."""
    clean = total = 0
    for name, data in files.items():
        parts = [read_stl(data)] if name.endswith(".stl") else read_3mf_parts(data) if name.endswith(".3mf") else []
        for part in parts:
            total += 1
            try:
                check_file(part, name)
                clean += 1
            except CpapfitError as exc:
                print(f"  {name}: {exc}")
    return clean, total


def mould_row(name: str, mask: str, d, files: tuple[int, int]) -> str:
    """A design's row of the files table: files clean, each mould part's draft, the mould's build time."""
    start = time.perf_counter()
    mould(d.cushion, d.solid)
    seconds = time.perf_counter() - start
    cells = []
    for part in PARTS:
        x = d.mould_draft[part]
        cells.append(f"{100 * x.undercut_fraction:.1f} / {100 * x.below_min_fraction:.1f}{' *' if x.meets_target else ''}")
    cells[-1] += f" ({d.mould_draft['mould_core'].pull_name.split('through the ')[-1]})"
    return f"| {name} | {mask} | {files[0]}/{files[1]} | {' | '.join(cells)} | {seconds:.1f} |"


def frame_row(name: str, mask: str, d, frame_stl: bytes) -> str:
    """A design's row of the frame table: the written frame.stl's cone, the vents, dead space, the
    assembly and the frame's build time."""
    start = time.perf_counter()
    check_closed(build_frame(d.cushion, d.solid).mesh, "frame")
    built = time.perf_counter() - start
    cone = np.abs(sliced_diameters(read_stl(frame_stl), d.frame.port_tip, d.frame.port_axis, FROM_TIP) - cone_diameter_mm(FROM_TIP)).max()
    vent = np.abs(d.frame.vents.flow_l_min(TARGET_CMH2O) / np.array(TARGET_L_MIN) - 1).max()
    fit = d.frame.assembly
    return (f"| {name} | {mask} | {cone:.4f} | {vent:.3f} | {d.dead_space_ml:.1f} | {d.cushion.params.frame_clearance_mm:.1f} | "
            f"{fit['interference_mm3']:.4f} | {fit['airway_closed']} ({fit['joined_genus']}) | {built:.2f} |")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ict", type=int, nargs="*", default=list(range(1, 9)), help="ICT subjects' seeds")
    ap.add_argument("--template", type=int, nargs="*", default=list(range(1, 9)), help="template-made subjects' seeds")
    args = ap.parse_args()
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"cpapfit {cpapfit.__version__} at {commit}, {platform.machine()}, python {platform.python_version()}", flush=True)
    moulds, frames, refused = [], [], []
    files, met, worst = [0, 0], {p: [0, 0] for p in PARTS}, {p: 0.0 for p in PARTS}
    with tempfile.TemporaryDirectory() as tmp:
        for name, path in subjects(args.ict, args.template, Path(tmp)):
            scan = load_scan(path)
            try:
                placement = place_template(scan)
            except CpapfitError as exc:
                refused.append(f"| {name} | both | refused: {exc} |")
                print(refused[-1], flush=True)
                continue
            for mask in ("nasal", "oronasal"):
                try:
                    d = design(scan, mask, placement=placement, stock=None)
                    written = design_files(d, scan)
                except CpapfitError as exc:
                    refused.append(f"| {name} | {mask} | refused: {exc} |")
                    print(refused[-1], flush=True)
                    continue
                clean = reread(written)
                files = [files[0] + clean[0], files[1] + clean[1]]
                for part in PARTS:
                    met[part] = [met[part][0] + d.mould_draft[part].meets_target, met[part][1] + 1]
                    worst[part] = max(worst[part], d.mould_draft[part].undercut_fraction)
                moulds.append(mould_row(name, mask, d, clean))
                frames.append(frame_row(name, mask, d, written["frame.stl"]))
                print(moulds[-1], frames[-1], sep="\n", flush=True)
    print("\n| subject | mask | parts clean | left | right | face plate | core (pull) | mould (s) |\n|---|---|---|---|---|---|---|---|")
    print(*moulds, sep="\n")
    print("\n| subject | mask | cone worst (mm) | vent worst error | dead space (ml) | ring clearance (mm) | interference (mm3) | "
          "airway closed (genus) | frame build (s) |\n|---|---|---|---|---|---|---|---|---|")
    print(*frames, *refused, sep="\n")
    print(f"\nparts clean as re-read: {files[0]}/{files[1]}")
    for part in PARTS:
        print(f"{part}: meets the target on {met[part][0]}/{met[part][1]} designs; largest undercut {100 * worst[part]:.1f} %")


if __name__ == "__main__":
    main()
