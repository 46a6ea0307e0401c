"""Custom vs generic cushion at 10 cmH2O on synthetic subjects and the shared
real scans: leak, safe-window fraction, pressure CV and peak, sealing force.

Usage: .venv/bin/python bench/fit_evaluation.py [--seeds 20]   (prints a Markdown table)
"""

import argparse
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from cpapfit.io import load_scan
from cpapfit.io.phantom import write_phantom
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.pipeline import design, evaluate, evaluated_cushions, face_for

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
KEYS = ("leak_l_min", "window_fraction", "pressure_cv", "pressure_max_kpa", "seal_force_n", "rim_covered_fraction")


def cells(summary: dict) -> list[str]:
    return ["-" if summary[k] is None else f"{summary[k]:.2f}" for k in KEYS]


def generic_fit(d, scan):
    """The generic cushion (the template's design placed by the similarity) pressed onto the scan at
    the custom cushion's headgear force."""
    face = face_for(scan, d.alignment, d.registration)
    cushions = evaluated_cushions(d.alignment, d.solid, d.contact.mask, d.cushion.params)
    return evaluate(face, cushions, d.cushion.params, d.fit_params, d.fits["custom"].force_n)["generic"]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    seeds = ap.parse_args().seeds
    print(f"machine: {platform.machine()}, Python {platform.python_version()}; CPAP 10 cmH2O; both cushions at the custom one's "
          "headgear force\n")
    head = " | ".join(KEYS)
    print(f"| scan | mask | force N | custom: {head} | generic: {head} |")
    print("|" + "---|" * (3 + 2 * len(KEYS)))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cases = []
        for seed in range(1, seeds + 1):
            write_phantom(make_phantom(seed), Path(tmp) / f"s{seed}")
            cases += [(f"phantom {seed}", Path(tmp) / f"s{seed}", mask) for mask in ("nasal", "oronasal")]
        for name in ("fran_cyberware/fran.obj", "rgbd_truedepth_mannequin"):
            if (SHARED / name).exists():
                cases += [(name.split("/")[0], SHARED / name, mask) for mask in ("nasal", "oronasal")]
        for name, path, mask in cases:
            t0 = time.perf_counter()
            try:
                scan = load_scan(path)
                d = design(scan, mask)
            except Exception as exc:  # a bench row, not a crash
                print(f"| {name} | {mask} | failed: {exc} |")
                continue
            c, g = d.fits["custom"].summary(), generic_fit(d, scan).summary()
            rows.append((name, mask, c, g))
            print(f"| {name} | {mask} | {d.fits['custom'].force_n:.1f} | {' | '.join(cells(c))} | {' | '.join(cells(g))} | "
                  f"<!-- {time.perf_counter() - t0:.0f} s -->", flush=True)
    synthetic = [r for r in rows if r[0].startswith("phantom")]
    for label, subset in (("synthetic", synthetic), ("all", rows)):
        c = [r[2] for r in subset]
        g = [r[3] for r in subset]
        ok = sum(x["leak_l_min"] <= 1.0 and x["window_fraction"] >= 0.95 for x in c)
        worse = sum((y["pressure_cv"] or np.inf) >= 2 * (x["pressure_cv"] or 0) or y["leak_l_min"] > x["leak_l_min"] for x, y in zip(c, g))
        print(f"\n{label}: {len(subset)} designs; custom leak <= 1 L/min and window >= 95 %: {ok}/{len(subset)}; "
              f"generic measurably worse (CV >= 2x or more leak): {worse}/{len(subset)}; "
              f"median CV custom {np.median([x['pressure_cv'] for x in c]):.3f} vs generic "
              f"{np.median([y['pressure_cv'] or np.nan for y in g]):.3f}; "
              f"max custom leak {max(x['leak_l_min'] for x in c):.2f} L/min; min custom window {min(x['window_fraction'] for x in c):.3f}")


if __name__ == "__main__":
    main()
