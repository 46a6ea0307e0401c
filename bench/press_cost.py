"""The fit model's cost per cushion pressed: `fit_rim` (the equilibrium at the recommended force and
the bisection for the seal force, a dozen equilibria) on a design's own rim, the seal flange as a
beam along the rim and without. CPU time per call (process time, the least of --repeat runs), so
that a shared machine's load does not count.

Usage: .venv/bin/python bench/press_cost.py [--seed 1] [--mask nasal] [--repeat 20]
"""

import argparse
import platform
import tempfile
import time
from dataclasses import replace

from cpapfit import __version__
from cpapfit.api import load_scan, phantom
from cpapfit.evaluation.fit import FitParams, fit_rim
from cpapfit.pipeline import design, face_for


def cost_ms(rim, face, params: FitParams, repeat: int) -> float:
    """Least CPU time (ms) of one `fit_rim` over `repeat` runs."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fit_rim(rim, face, 5.0, None, params)
        best = min(best, time.process_time() - t0)
    return 1e3 * best


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--mask", default="nasal")
    ap.add_argument("--repeat", type=int, default=20)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        scan = load_scan(phantom(args.seed, f"{tmp}/subject"))
    d = design(scan, args.mask)
    custom, face = d.fits["custom"], face_for(scan, d.alignment, d.registration)
    print(f"cpapfit {__version__}, {platform.machine()}, Python {platform.python_version()}; phantom {args.seed}, "
          f"{args.mask}: {int(custom.rim.covered.sum())} of {len(custom.rim.covered)} rim points covered")
    for thickness in (None, d.cushion.params.wall_mm):
        params = replace(d.fit_params, flange_thickness_mm=thickness)
        print(f"flange as a beam {thickness} mm thick: fit_rim {cost_ms(custom.rim, face, params, args.repeat):.1f} ms CPU")


if __name__ == "__main__":
    main()
