"""Sweeps fused into one scan: accuracy on synthetic ICT sweeps, and the shared real sweep designed.

Synthetic (`cpapfit.synthetic.ict_sweep`): per seed, a sweep of --frames frames is written and fused as
`cpapfit` reads it; the fused surface is measured against the truth (every template vertex, and
the masks' contact bands: distance to the fused mesh, mm), and the template registered on the
fused scan (its face, as `cpapfit` registers it, and the whole fused scan) against the one registered
on the sweep's most frontal frame alone (contact-band vertices to their true places, mm). Real: `cpapfit design` of ../shared/data/truedepth_sweep_mannequin
for both masks: rescan advised, the seal over scanned skin, wall time and CPU seconds (user +
sys, which a busy machine inflates less than the wall time), the load average before and after;
designed twice, the two output folders compared file by file.

    .venv/bin/python bench/sweep_fusion.py [--seeds 5] [--first 1] [--frames 9] [--real] [--no-synthetic]
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

from cpapfit import __version__
from cpapfit.align.nonrigid import NonrigidParams
from cpapfit.synthetic.ict_sweep import make_ict_sweep
from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.phantom import write_sweep
from cpapfit.io.write import write_files
from cpapfit.synthetic.accuracy import surface_distance
from cpapfit.pipeline import place_template
from cpapfit.template import load_template, mask_region

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "truedepth_sweep_mannequin"


def band_error(scan, truth: np.ndarray, params: NonrigidParams = NonrigidParams()) -> np.ndarray:
    """(K,) mm: the registered template's contact-band vertices to their true places."""
    band = mask_region(load_template())
    return np.linalg.norm(place_template(scan, params=params).registration.vertices[band] - truth[band], axis=1)


def synthetic_row(seed: int, frames: int, tmp: Path) -> dict:
    sweep = make_ict_sweep(seed, frames)
    folder = tmp / f"sweep{seed}"
    write_sweep(sweep, folder)
    start = time.perf_counter()
    fused = load_scan(folder)
    seconds = time.perf_counter() - start
    truth = sweep[0].surface
    every = surface_distance(truth, fused.vertices, fused.faces)
    band = every[mask_region(load_template())]
    frontal = len(sweep) // 2
    single = tmp / f"frame{seed}"
    ph = sweep[frontal]
    write_files(single, capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
    from_sweep, from_frame = band_error(fused, truth), band_error(load_scan(single), ph.surface)
    whole = band_error(fused, truth, NonrigidParams(fused_reach_mm=None))
    return {"seed": seed, "frames": frames, "fuse_s": seconds, "note": fused.units_note.split("; ", 1)[1],
            "median": np.median(every), "p95": np.percentile(every, 95), "band_median": np.median(band),
            "band_p95": np.percentile(band, 95), "sweep_band_mean": from_sweep.mean(), "sweep_band_p95": np.percentile(from_sweep, 95),
            "frame_band_mean": from_frame.mean(), "frame_band_p95": np.percentile(from_frame, 95), "whole_band_mean": whole.mean()}


def real_row(mask: str, out: Path) -> dict:
    load = os.getloadavg()[0]
    before, start = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "cpapfit", "design", str(REAL), "--mask", mask, "--out", str(out), "--quiet"],
                         capture_output=True, text=True, env=os.environ | {"SOURCE_DATE_EPOCH": "0"})  # the report's run date fixed
    seconds, after = time.perf_counter() - start, resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    timing = {"mask": mask, "seconds": round(seconds, 1), "cpu_s": round(cpu, 1), "load": (load, os.getloadavg()[0])}
    if run.returncode:
        return timing | {"error": run.stderr.strip()}
    fit = json.loads((out / "fit.json").read_text())
    fused = trimesh.load(out / "fused_scan.ply", process=False)
    return timing | {"rescan_advised": fit["rescan_advised"], "warnings": len(fit["warnings"]),
                     "seal_on_scan": fit["seal_on_scan_fraction"], "coverage": fit["quality"]["coverage"],
                     "fused_vertices": len(fused.vertices)}


def differing(a: Path, b: Path) -> list[str]:
    """The files of output folder `a` whose bytes differ in `b` (or are missing there)."""
    return [p.name for p in sorted(a.iterdir()) if not (b / p.name).is_file() or p.read_bytes() != (b / p.name).read_bytes()]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--first", type=int, default=1, help="the first seed")
    ap.add_argument("--frames", type=int, default=9)
    ap.add_argument("--real", action="store_true", help="also design the shared real sweep (both masks, nasal twice)")
    ap.add_argument("--no-synthetic", action="store_true", help="skip the synthetic sweeps")
    args = ap.parse_args()
    print(f"cpapfit {__version__}")
    with tempfile.TemporaryDirectory() as tmp:
        print("| seed | frames | fused | fuse s | surface median | p95 | bands median | p95 | design from sweep: band mean | p95 | from frontal frame: mean | p95 | whole fused scan registered: mean |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        rows = []
        for seed in range(args.first, args.first + (0 if args.no_synthetic else args.seeds)):
            r = synthetic_row(seed, args.frames, Path(tmp))
            rows.append(r)
            print(f"| {seed} | {r['frames']} | {r['note']} | {r['fuse_s']:.1f} | {r['median']:.3f} | {r['p95']:.3f} | "
                  f"{r['band_median']:.3f} | {r['band_p95']:.3f} | {r['sweep_band_mean']:.3f} | {r['sweep_band_p95']:.3f} | "
                  f"{r['frame_band_mean']:.3f} | {r['frame_band_p95']:.3f} | {r['whole_band_mean']:.3f} |", flush=True)
        if rows:
            sweep, frame, whole = (np.array([r[k] for r in rows]) for k in ("sweep_band_mean", "frame_band_mean", "whole_band_mean"))
            print(f"design from the sweep nearer the truth than from the frontal frame on {int((sweep < frame).sum())} of "
                  f"{len(rows)}; band mean over the seeds {sweep.mean():.3f} mm against {frame.mean():.3f} (the sweep's minus "
                  f"the frame's: mean {(sweep - frame).mean():+.3f} mm, standard deviation {(sweep - frame).std(ddof=1) if len(rows) > 1 else 0:.3f}); "
                  f"the whole fused scan registered: {whole.mean():.3f} mm, nearer than the frame on {int((whole < frame).sum())}")
        if args.real and REAL.is_dir():
            for mask in ("nasal", "oronasal"):
                print(real_row(mask, Path(tmp) / mask), flush=True)
            print(real_row("nasal", Path(tmp) / "again"), flush=True)
            print("nasal designed twice, files differing:", differing(Path(tmp) / "nasal", Path(tmp) / "again"))


if __name__ == "__main__":
    main()
