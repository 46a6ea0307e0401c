"""Wall-clock time of `cpapfit design` (the whole chain, as a user runs it) on a synthetic subject
and on the shared fran scan (skipped without ../shared), with the CPU time of the run (its
processes' user + system time, which other jobs on the machine change far less) and the load
average when it started.

Usage: .venv/bin/python bench/design_time.py [--repeat N]
"""

import argparse
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


def run(*args: str) -> tuple[float, float]:
    """(wall seconds, CPU seconds of the run's processes) of `cpapfit ARGS`."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "cpapfit", *args], check=True, capture_output=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=3)
    repeat = parser.parse_args().repeat
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as tmp:
        run("phantom", "--seed", "3", "--out", f"{tmp}/p3")
        cases = [("phantom seed 3", f"{tmp}/p3", mask) for mask in ("nasal", "oronasal")]
        if (SHARED / "fran_cyberware" / "fran.obj").exists():
            cases.append(("fran", str(SHARED / "fran_cyberware" / "fran.obj"), "nasal"))
        for name, scan, mask in cases:
            walls = []
            for _ in range(repeat):
                load = os.getloadavg()[0]
                wall, cpu = run("design", scan, "--mask", mask, "--out", f"{tmp}/out")
                walls.append(wall)
                print(f"cpapfit design {name} --mask {mask}: {wall:.1f} s (process start to exit), CPU {cpu:.1f} s, load {load:.1f}")
            print(f"  {name} {mask}: best {min(walls):.1f} s, median {statistics.median(walls):.1f} s")


if __name__ == "__main__":
    main()
