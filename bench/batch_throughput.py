"""Throughput of `cpapfit batch` (scans per minute) on synthetic subjects, with 1 and 2 local
worker processes, or on a running Dask cluster with --scheduler. Each run starts from an empty
output folder and is timed from process start to exit (cluster start-up included).

Usage: .venv/bin/python bench/batch_throughput.py [--scans 4] [--workers 1 2] [--scheduler ADDRESS]
"""

import argparse
import csv
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from cpapfit.io.phantom import write_phantom
from cpapfit.phantom import make_phantom


def batch(scans: Path, out: Path, *options: str) -> float:
    """Seconds for one `cpapfit batch` run (process start to exit)."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "cpapfit", "batch", str(scans), "--out", str(out), "--quiet", *options], check=True)
    return time.perf_counter() - t0


def report(label: str, n: int, seconds: float, out: Path) -> None:
    with open(out / "summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert all(r["status"] == "designed" for r in rows), rows
    per_scan = statistics.median(float(r["time (s)"]) for r in rows)
    print(f"{label}: {n} scans in {seconds:.1f} s = {60 * n / seconds:.1f} scans/min (median {per_scan:.1f} s per scan on its worker)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=4)
    ap.add_argument("--workers", type=int, nargs="*", default=[1, 2], help="local worker counts to time (none: only --scheduler)")
    ap.add_argument("--scheduler", help="also time a run on this running Dask cluster")
    args = ap.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as tmp:
        scans = Path(tmp) / "scans"
        for seed in range(args.scans):
            write_phantom(make_phantom(seed), scans / f"seed{seed}")
        for w in args.workers:
            out = Path(tmp) / f"out-{w}"
            report(f"local cluster, {w} worker process(es)", args.scans, batch(scans, out, "--workers", str(w)), out)
        if args.scheduler:
            out = Path(tmp) / "out-scheduler"
            report(f"cluster at {args.scheduler}", args.scans, batch(scans, out, "--scheduler", args.scheduler), out)


if __name__ == "__main__":
    main()
