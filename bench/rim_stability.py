"""How far the fit's figures move when the finished cushion moves a little: the rim's sampling.

A head mesh designed for a nasal mask (`pipeline.design`, no stock comparison), then its cushion
moved rigidly by small random offsets (four of σ 0.01 mm, three of σ 0.05 mm per axis; fixed seed)
and pressed again awake and asleep (`pipeline.pressed_asleep`): the headgear force set, the awake
peak and the force that seals the mask pushed 3 mm to the right, each against the unmoved cushion's.
A shift this small changes no physics; what moves the figures is each of the 256 sectors choosing
its rim point among the cushion's vertices refined to `--refine` mm (`evaluation/rim.REFINE_MM`).

Usage: .venv/bin/python bench/rim_stability.py SCAN [--refine 0.7]
"""

import argparse
import time

import numpy as np

from cpapfit.evaluation import rim
from cpapfit.io import load_scan
from cpapfit.pipeline import design, face_for, pressed_asleep


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("scan")
    ap.add_argument("--refine", type=float, default=rim.REFINE_MM, help="longest cushion edge when finding the rim, mm")
    args = ap.parse_args()
    rim.REFINE_MM = args.refine
    scan = load_scan(args.scan)
    d = design(scan, "nasal", stock=None)
    face = face_for(scan, d.alignment, d.registration, d.solid.vertices)
    rng = np.random.default_rng(0)
    shifts = [np.zeros(3)] + [rng.normal(0, 0.01, 3) for _ in range(4)] + [rng.normal(0, 0.05, 3) for _ in range(3)]
    print(f"refined to {args.refine:g} mm")
    print("| shift (mm) | headgear force (N) | awake peak (kPa) | pushed 3 mm right: seal force (N) | s |")
    print("|---|---|---|---|---|")
    rows = []
    for shift in shifts:
        start = time.perf_counter()
        solid = d.solid.copy()
        solid.apply_translation(shift)
        fits, states = pressed_asleep(face, {"custom": solid}, "nasal")
        custom = fits["custom"]
        right = next(s for s in states if "right" in s.state.name).fits["custom"]
        rows.append((custom.force_n, custom.summary()["pressure_max_kpa"], right.seal_force_n))
        print(f"| {np.round(shift, 3).tolist()} | {rows[-1][0]:.3f} | {rows[-1][1]:.3f} | {rows[-1][2]:.3f} | "
              f"{time.perf_counter() - start:.1f} |", flush=True)
    rows = np.array(rows)
    spread = (rows.max(axis=0) - rows.min(axis=0)) / rows[0]
    print(f"spread over the moves, of the unmoved cushion's: force {spread[0]:.1%}, peak {spread[1]:.1%}, "
          f"pushed right {spread[2]:.1%}")


if __name__ == "__main__":
    main()
