"""Stock cushions fitted as a clinic fits them (`cpapfit.stock_fit`), awake, on ICT Face Model subjects
(drawn from the full model, `--model`) and the shared real scans (`--real`): each face placed as
`design` places it, then every stock size of each mask seated at its best; per face and mask the
gauge's measure (and its percentile among the faces the sizes are made from), the gauge's size, the
best size by fit, and each size's force, leak, peak pressure (and where) and window; then, for each
face whose best size does not seal, its measure against the sizes' span and where it presses.

Usage: .venv/bin/python bench/stock_fit.py [--seeds 30] [--first 8000] [--workers 2] [--rows rows.jsonl]
       [--model NPZ | --model shipped] [--real]
"""

import argparse
import json
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from cpapfit import __version__
from cpapfit.errors import CpapfitError, NoStockSeat
from cpapfit.ict import load_ict
from cpapfit.synthetic.ict_phantom import ict_head_mesh
from cpapfit.io import load_scan
from cpapfit.pipeline import face_for, place_template
from cpapfit.cushion.population import gauge_mm, population_gauge
from cpapfit.cushion.stock import SIZE_PERCENTILES
from cpapfit.stock_fit import COMFORT_N, compared_stock
from cpapfit.template import MASKS
from ict_bench import ict_arguments, model_source, scan_of

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
REAL = {"fran": SHARED / "fran_cyberware" / "fran.obj", "truedepth frame": SHARED / "rgbd_truedepth_mannequin"}
SEAL_L_MIN, CAPILLARY_KPA = 5.0, 4.3


def run(job: tuple[str, str, Path | None]) -> list[dict]:
    """Every stock size of both masks on one face: ("ict", seed, model) or ("real", name, path)."""
    kind, name, source = job
    if kind == "ict":
        scan = scan_of(ict_head_mesh(int(name), model=load_ict(source)).mesh)
    else:
        scan = load_scan(source)
    try:
        placed = place_template(scan)
    except CpapfitError as exc:
        return [{"face": name, "mask": m, "outcome": "refused", "reason": str(exc)[:200]} for m in MASKS]
    face = face_for(scan, placed.alignment, placed.registration)
    rows = []
    for mask in MASKS:
        t0 = time.perf_counter()
        try:
            compared = compared_stock(mask, face, asleep=False)
        except NoStockSeat as exc:
            rows.append({"face": name, "mask": mask, "outcome": "refused", "reason": str(exc)[:200]})
            continue
        fits = {f.size: f for f in compared.sizes}
        sizes = {size: {"offset_mm": list(f.offset_mm), "sealed": f.sealed, "force_n": f.fit.force_n,
                        **{k: f.fit.summary()[k] for k in ("leak_l_min", "pressure_max_kpa", "pressure_max_region",
                                                           "window_fraction", "rim_covered_fraction")}}
                 for size, f in fits.items()}
        measure = gauge_mm(mask, np.asarray(face.registered.vertices))
        rows.append({"face": name, "mask": mask, "outcome": "fitted", "gauge": compared.gauge, "gauge_mm": measure,
                     "gauge_percentile": 100.0 * float(np.mean(population_gauge(mask) < measure)),
                     "best": next(iter(fits)), "sizes": sizes, "seconds": time.perf_counter() - t0})
    return rows


NOT_SEATED = {"leak_l_min": float("nan"), "pressure_max_kpa": float("nan")}  # a size with no seat on the face


def seals(row: dict, size: str) -> bool:
    """The size seals awake: at most SEAL_L_MIN and the peak at most CAPILLARY_KPA (not where it had no seat)."""
    s = row["sizes"].get(size, NOT_SEATED)
    return s["leak_l_min"] <= SEAL_L_MIN and s["pressure_max_kpa"] <= CAPILLARY_KPA


def table(rows: list[dict]) -> str:
    """Markdown: per face and mask, the gauge's and the best size and each one's numbers."""
    out = ["| face | mask | gauge measure (mm, population percentile) | gauge | best | best: force (N) | leak (L/min) | peak (kPa) | where "
           "| window | covered | gauge's size: leak | peak | seals (best / gauge) |",
           "|---" * 14 + "|"]
    for r in rows:
        if r["outcome"] != "fitted":
            out.append(f"| {r['face']} | {r['mask']} | refused: {r['reason'][:80]} |" + " |" * 11)
            continue
        b, g = r["sizes"][r["best"]], r["sizes"].get(r["gauge"], NOT_SEATED)
        out.append(f"| {r['face']} | {r['mask']} | {r['gauge_mm']:.1f} ({r['gauge_percentile']:.0f}) | {r['gauge']} | {r['best']} "
                   f"| {b['force_n']:.1f} | {b['leak_l_min']:.1f} | {b['pressure_max_kpa']:.2f} | {b['pressure_max_region']} "
                   f"| {100 * b['window_fraction']:.0f} % | {100 * b['rim_covered_fraction']:.0f} % "
                   f"| {g['leak_l_min']:.1f} | {g['pressure_max_kpa']:.2f} | {'yes' if seals(r, r['best']) else 'no'} / "
                   f"{'yes' if seals(r, r['gauge']) else 'no'} |")
    return "\n".join(out)


def summary(rows: list[dict]) -> str:
    """Per mask: the share of faces whose best and whose gauge's size seal, and the gauge's agreement."""
    out = []
    for mask in MASKS:
        got = [r for r in rows if r["mask"] == mask and r["outcome"] == "fitted"]
        if got:
            best = np.mean([seals(r, r["best"]) for r in got])
            gauge = np.mean([seals(r, r["gauge"]) for r in got])
            agree = np.mean([r["gauge"] == r["best"] for r in got])
            out.append(f"{mask}: best size seals on {100 * best:.0f} % of {len(got)}, the gauge's on {100 * gauge:.0f} %, "
                       f"gauge = best on {100 * agree:.0f} %")
            out += [f"  not sealed: {r['face']}, gauge measure at percentile {r['gauge_percentile']:.0f} of the population "
                    f"(sizes S-L at {SIZE_PERCENTILES['S']:g}-{SIZE_PERCENTILES['L']:g}), "
                    f"peak {r['sizes'][r['best']]['pressure_max_kpa']:.2f} kPa ({r['sizes'][r['best']]['pressure_max_region']})"
                    for r in got if not seals(r, r["best"])]
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ict_arguments(ap)
    ap.add_argument("--real", action="store_true", help="also the shared real scans")
    args = ap.parse_args()
    source = model_source(args)
    print(f"cpapfit {__version__}, {platform.machine()}, Python {platform.python_version()}; ICT seeds "
          f"{args.first}-{args.first + args.seeds - 1}, head meshes; headgear at most {COMFORT_N:g} N; {args.workers} workers")
    jobs = [("ict", str(seed), source) for seed in range(args.first, args.first + args.seeds)]
    jobs += [("real", name, path) for name, path in REAL.items() if args.real and path.exists()]
    rows, t0 = [], time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        for done in pool.map(run, jobs):
            rows += done
            for r in done:
                print(" ", r["face"], r["mask"], r["outcome"], r.get("best", r.get("reason", "")), flush=True)
    if args.rows:
        args.rows.write_text("".join(json.dumps(r) + "\n" for r in rows))
    print()
    print(table(rows))
    print()
    print(summary(rows))
    print(f"\ntotal time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
