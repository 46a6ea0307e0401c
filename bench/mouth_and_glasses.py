"""An open mouth, or glasses: synthetic subjects (framed template-made ones, or ICT faces) with the
jaw dropped or a glasses frame on, designed end to end. Printed per subject and opening: the mean error of the
registered mask region against the truth (mm), the seal curve's largest distance from the true skin
(mm), the lips' opening as detected (mm), the area in front of the face (mm²), and the outcome
(flags, or the gate that refused). Gates: `lips_apart_mm` (oronasal), `in_front_mm2`. With --mesh,
each capture is made a mesh scan turned at random, coloured or bare (landmarks from renders).
With --population ict the subjects are ICT faces (teeth, gums and tongue behind the lips, the
model's own jawOpen), as `cpapfit phantom --seed S --mouth-open MM` writes them: captures, or with
--mesh colour the whole coloured head mesh (template frame, not turned), as `--mesh` writes it.

Usage: .venv/bin/python bench/mouth_and_glasses.py [--seeds 6] [--first 100] [--mm 0,2,4,8] [--glasses]
       [--mask oronasal] [--mesh colour|bare] [--population template|ict]
"""

import argparse
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from cpapfit.errors import CpapfitError
from cpapfit.io import load_scan
from cpapfit.io.capture import load_capture
from cpapfit.io.phantom import HEAD, write_head_mesh, write_phantom
from cpapfit.synthetic.ict_phantom import ict_head_mesh, make_ict_phantom
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.synthetic.camera import FRAMED
from cpapfit.pipeline import design
from cpapfit.template import load_template
from landmarks_alignment import as_mesh


def template_subject(seed: int, mm: float, glasses: bool, mesh: str | None):
    """(scan, (N, 3) mm truth) of framed template subject `seed`, lower lip moved `mm`, with
    `glasses` or not (as a `mesh` scan turned at random)."""
    ph = make_phantom(seed, pose=FRAMED, mouth_open_mm=mm, glasses=glasses)
    with tempfile.TemporaryDirectory() as tmp:
        write_phantom(ph, Path(tmp))
        scan = load_capture(Path(tmp))
    if not mesh:
        return scan, ph.surface
    turn = Rotation.random(random_state=seed).as_matrix()
    return as_mesh(scan, turn, mesh == "colour"), ph.surface @ turn.T


def ict_subject(seed: int, mm: float, mesh: bool):
    """(scan, (N, 3) mm truth) of ICT subject `seed`, lower lip dropped `mm`: a capture, or its head mesh."""
    with tempfile.TemporaryDirectory() as tmp:
        if mesh:
            head = ict_head_mesh(seed, mouth_open_mm=mm)
            write_head_mesh(head, Path(tmp))
            return load_scan(Path(tmp) / HEAD), head.truth
        ph = make_ict_phantom(seed, mouth_open_mm=mm)
        write_phantom(ph, Path(tmp))
        return load_capture(Path(tmp)), ph.surface


def one(scan, truth: np.ndarray, seed: int, mm: float, mask: str) -> str:
    """A table row: the design of `scan` (subject `seed`, lower lip moved `mm`) against its (N, 3) mm `truth`."""
    try:
        d = design(scan, mask)
    except CpapfitError as exc:
        return f"| {seed} | {mm:g} | - | - | - | - | refused: {str(exc).split('mask (')[-1].split(';')[0].replace('):', ':', 1)} |"
    band = load_template().regions[mask].band
    err = float(np.linalg.norm(d.registration.vertices[band] - truth[band], axis=1).mean())
    off_skin = float(cKDTree(truth).query(d.contact.curve)[0].max())
    values = {g.code: g.value for g in d.quality.gates}
    flags = ", ".join(g.code for g in d.quality.flags) or "none"
    return (f"| {seed} | {mm:g} | {err:.2f} | {off_skin:.2f} | {d.alignment.landmarks.lips_apart_mm:.1f} | "
            f"{values['in_front_mm2']:.0f} | flagged: {flags} |")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--first", type=int, default=100)
    ap.add_argument("--mm", default="0,2,4,8", help="how far the lower lip moves, mm, comma-separated")
    ap.add_argument("--glasses", action="store_true", help="a glasses frame on every subject")
    ap.add_argument("--mask", default="oronasal")
    ap.add_argument("--mesh", choices=("colour", "bare"), default=None, help="as a mesh scan: template subjects turned at random, ICT ones their head mesh")
    ap.add_argument("--population", choices=("template", "ict"), default="template")
    args = ap.parse_args()
    if args.population == "ict" and (args.glasses or args.mesh == "bare"):
        ap.error("--population ict: no glasses, and its head meshes are coloured (--mesh colour)")
    kind = f"as {args.mesh} meshes" if args.mesh else "as captures"
    worn = ", wearing glasses" if args.glasses else ""
    who = "ICT subjects" if args.population == "ict" else "framed subjects"
    print(f"{args.mask} mask; {who} {args.first}-{args.first + args.seeds - 1}{worn}, {kind}")
    print("| subject | lower lip moved (mm) | mask region error, mean (mm) | seal to true skin, max (mm) | "
          "lips apart, detected (mm) | in front (mm²) | outcome |")
    print("|---|---|---|---|---|---|---|")
    for seed in range(args.first, args.first + args.seeds):
        for mm in map(float, args.mm.split(",")):
            scan, truth = (ict_subject(seed, mm, bool(args.mesh)) if args.population == "ict"
                           else template_subject(seed, mm, args.glasses, args.mesh))
            print(one(scan, truth, seed, mm, args.mask), flush=True)


if __name__ == "__main__":
    main()
