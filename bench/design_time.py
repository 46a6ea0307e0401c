"""Wall-clock time of `cpapfit design` (the whole chain, as a user runs it) on a synthetic subject,
on that subject's surface as a dense mesh (1.6 M triangles, PLY in metres: a structured-light or
photogrammetry scanner's output) and on the shared fran scan (skipped without ../shared), with
the CPU time of the run (its processes' user + system time, which other jobs on the machine
change far less), the load average when it started and the largest resident memory of any run
so far.

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

import trimesh

from cpapfit.synthetic.template_phantom import make_phantom

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


def run(*args: str) -> tuple[float, float]:
    """(wall seconds, CPU seconds of the run's processes) of `cpapfit ARGS`."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "cpapfit", *args], capture_output=True, text=True)
    if done.returncode:
        sys.exit(f"cpapfit {' '.join(args)} failed ({done.returncode}): {done.stderr.strip()}")
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def dense_mesh(path: Path) -> None:
    """Seed 3's true surface subdivided to 0.35 mm edges (~1.6 M triangles), written in metres."""
    ph = make_phantom(3)
    vertices, faces = trimesh.remesh.subdivide_to_size(ph.surface, ph.faces, 0.35)
    trimesh.Trimesh(vertices / 1000.0, faces, process=False).export(path)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=3)
    repeat = parser.parse_args().repeat
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as tmp:
        run("phantom", "--seed", "3", "--population", "template", "--out", f"{tmp}/p3")
        dense_mesh(Path(tmp) / "dense.ply")
        cases = [("phantom seed 3", f"{tmp}/p3", mask) for mask in ("nasal", "oronasal")]
        cases.append(("phantom seed 3 as a dense mesh", f"{tmp}/dense.ply", "nasal"))
        if (SHARED / "fran_cyberware" / "fran.obj").exists():
            cases.append(("fran", str(SHARED / "fran_cyberware" / "fran.obj"), "nasal"))
        for name, scan, mask in cases:
            walls = []
            for _ in range(repeat):
                load = os.getloadavg()[0]
                wall, cpu = run("design", scan, "--mask", mask, "--out", f"{tmp}/out")
                walls.append(wall)
                peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024**2
                print(f"cpapfit design {name} --mask {mask}: {wall:.1f} s (process start to exit), CPU {cpu:.1f} s, "
                      f"load {load:.1f}, peak memory so far {peak:.1f} GB")
            print(f"  {name} {mask}: best {min(walls):.1f} s, median {statistics.median(walls):.1f} s")


if __name__ == "__main__":
    main()
