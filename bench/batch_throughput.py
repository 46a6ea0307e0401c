"""Throughput of `cpapfit batch` (scans per minute) on synthetic subjects, with 1 and 2 local
worker processes, or on a running Dask cluster with --scheduler. Each run starts from an empty
output folder and is timed from process start to exit (cluster start-up included).

Usage: .venv/bin/python bench/batch_throughput.py [--scans 4] [--workers 1 2] [--scheduler ADDRESS]
"""

import argparse
import csv
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from cpapfit.io.phantom import write_phantom
from cpapfit.synthetic.template_phantom import make_phantom


def children_cpu() -> float:
    """CPU seconds (user + system) of the finished child processes and their own reaped children."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def batch(scans: Path, out: Path, *options: str) -> tuple[float, float]:
    """(wall seconds, CPU seconds of the batch process and its local workers) for one
    `cpapfit batch` run, process start to exit."""
    t0, cpu0 = time.perf_counter(), children_cpu()
    subprocess.run([sys.executable, "-m", "cpapfit", "batch", str(scans), "--out", str(out), "--quiet", *options], check=True)
    return time.perf_counter() - t0, children_cpu() - cpu0


def report(label: str, n: int, seconds: tuple[float, float], out: Path) -> None:
    """One line: throughput, time per scan, CPU per scan (the machine's other load shows in the gap)."""
    with open(out / "summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert all(r["status"] == "designed" for r in rows), rows
    per_scan = statistics.median(float(r["time (s)"]) for r in rows)
    wall, cpu = seconds
    print(
        f"{label}: {n} scans in {wall:.1f} s = {60 * n / wall:.1f} scans/min (median {per_scan:.1f} s per scan on its "
        f"worker; {cpu / n:.1f} CPU s per scan in local processes)"
    )


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
            print(f"load average (1 min) before: {os.getloadavg()[0]:.1f}")
            out = Path(tmp) / f"out-{w}"
            report(f"local cluster, {w} worker process(es)", args.scans, batch(scans, out, "--workers", str(w)), out)
        if args.scheduler:
            out = Path(tmp) / "out-scheduler"
            report(f"cluster at {args.scheduler}", args.scans, batch(scans, out, "--scheduler", args.scheduler), out)


if __name__ == "__main__":
    main()
