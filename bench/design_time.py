"""Wall-clock time of `cpapfit design` (the whole chain, as a user runs it) on a synthetic subject,
on that subject's surface as a dense mesh (1.08 M vertices, 2.1 M triangles, PLY in metres: a
structured-light or photogrammetry scanner's output) and on the shared fran scan (skipped without ../shared), with
the CPU time of the run (its processes' user + system time, which other jobs on the machine
change far less), the load average when it started and the largest resident memory of any run
so far.

With --against DIR (another source tree of cpapfit, e.g. a git worktree of an earlier commit), the
real-sized cases instead (phantom seed 3's capture, ICT heads 8003 and 8020 as PLY, fran, the
TrueDepth frame; both masks but the frame's oronasal, which its scan hole refuses) are designed
in turn by that tree, by this one, and by this one with `--stock none` (no stock comparison),
each run from a scratch folder with its tree first on PYTHONPATH, and each case's medians and
their ratios to the other tree's are printed.

With --stages, each case is designed once more with `--verbose` and the wall time of each stage
the command reports is printed beside the whole, with the CPU seconds both its processes used in
that stage (the stages run while a worker process seats the stock sizes, so a stage's wall time is
not its own cost; CPU over wall is the cores the stage kept busy, at most 2 here).

Usage: .venv/bin/python bench/design_time.py [--repeat N] [--against DIR | --stages]
"""

import argparse
import os
import platform
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import trimesh

from cpapfit.ict import load_ict
from cpapfit.synthetic.ict_phantom import ict_head_mesh
from cpapfit.synthetic.template_phantom import make_phantom
from ict_bench import FULL_MODEL

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


def run(*args: str, tree: Path | None = None, cwd: str | None = None) -> tuple[float, float]:
    """(wall seconds, CPU seconds of the run's processes) of `cpapfit ARGS` (`tree`: that source tree first on PYTHONPATH)."""
    env = os.environ | {"PYTHONPATH": str(tree)} if tree else None
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "cpapfit", *args], capture_output=True, text=True, env=env, cwd=cwd)
    if done.returncode:
        sys.exit(f"cpapfit {' '.join(args)} failed ({done.returncode}): {done.stderr.strip()}")
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def stages(name: str, scan: str, mask: str, out: str) -> None:
    """One `--verbose` design of a case: each stage's wall seconds as the command reports them, and
    the CPU seconds its processes (this one and its worker) used in that stage, read from /proc as
    each stage's line arrives; start-up: from the process's start to its first stage's (its CPU
    counted in that stage's)."""
    t0 = time.perf_counter()
    done = subprocess.Popen([sys.executable, "-m", "cpapfit", "design", scan, "--mask", mask, "--out", out, "--verbose"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    marks = [(line, tree_cpu(done.pid), time.perf_counter() - t0) for line in done.stderr]
    if done.wait():
        sys.exit(f"cpapfit design {scan} failed ({done.returncode}): {''.join(line for line, *_ in marks).strip()}")
    wall, used, shown = time.perf_counter() - t0, 0.0, []
    for line, cpu, at in marks:
        timed = re.match(r"^  (.+): ([0-9.]+) s$", line)
        if timed:
            if not shown:
                shown.append(f"start-up {at - float(timed[2]):.2f}")
            shown.append(f"{timed[1]} {float(timed[2]):.2f} ({cpu - used:.2f})")
            used = cpu
    print(f"  {name} {mask} by stage, wall s (CPU s): {', '.join(shown)}; whole {wall:.1f} s, CPU {used:.1f} s to the last stage's end")


def tree_cpu(pid: int) -> float:
    """CPU seconds (user + system) process `pid` and its children have used so far, reaped ones
    included (Linux /proc)."""
    total = 0
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # gone meanwhile
            continue
        if stat.parent.name == str(pid):
            total += sum(int(f) for f in fields[11:15])
        elif int(fields[1]) == pid:
            total += int(fields[11]) + int(fields[12])
    return total / os.sysconf("SC_CLK_TCK")


def dense_mesh(path: Path) -> None:
    """Seed 3's true surface subdivided to 0.31 mm edges (1.08 M vertices, 2.1 M triangles), written in metres."""
    ph = make_phantom(3)
    vertices, faces = trimesh.remesh.subdivide_to_size(ph.surface, ph.faces, 0.31)
    trimesh.Trimesh(vertices / 1000.0, faces, process=False).export(path)


def against(other: Path, repeat: int, tmp: str) -> None:
    """Each real-sized case designed in turn by the `other` tree, this one, and this one with `--stock none` (module docstring)."""
    this = Path(__file__).resolve().parents[1]
    cases = [("phantom seed 3", f"{tmp}/p3", mask) for mask in ("nasal", "oronasal")]
    if FULL_MODEL.is_file():
        for seed in (8003, 8020):
            ict_head_mesh(seed, model=load_ict(FULL_MODEL)).mesh.export(f"{tmp}/ict{seed}.ply")
            cases += [(f"ICT head {seed}", f"{tmp}/ict{seed}.ply", mask) for mask in ("nasal", "oronasal")]
    if (SHARED / "fran_cyberware" / "fran.obj").exists():
        cases += [("fran", str(SHARED / "fran_cyberware" / "fran.obj"), mask) for mask in ("nasal", "oronasal")]
    if (SHARED / "rgbd_truedepth_mannequin").is_dir():
        cases.append(("TrueDepth frame", str(SHARED / "rgbd_truedepth_mannequin"), "nasal"))
    ways = {"other": (other, ()), "this": (this, ()), "this --stock none": (this, ("--stock", "none"))}
    print(f"other: {other}; this: {this}; {repeat} runs each, in turn; wall s (CPU s)")
    for name, scan, mask in cases:
        times = {way: [] for way in ways}
        for i in range(repeat):
            for k, (way, (tree, extra)) in enumerate(ways.items()):
                times[way].append(run("design", scan, "--mask", mask, "--out", f"{tmp}/out-{i}-{k}", "--quiet", *extra, tree=tree, cwd=tmp))
        median = {way: statistics.median(w for w, _ in runs) for way, runs in times.items()}
        shown = "; ".join(f"{way} {', '.join(f'{w:.1f} ({c:.1f})' for w, c in runs)}" for way, runs in times.items())
        print(f"{name} {mask}: {shown}; median ratio to other: this {median['this'] / median['other']:.2f}, "
              f"--stock none {median['this --stock none'] / median['other']:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--against", type=Path, default=None, help="another source tree to time the same cases with")
    parser.add_argument("--stages", action="store_true", help="also each stage's wall time, from one --verbose run per case")
    args = parser.parse_args()
    if args.against and args.stages:
        parser.error("--stages times this tree's default cases: not with --against")
    repeat = args.repeat
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as tmp:
        run("phantom", "--seed", "3", "--population", "template", "--out", f"{tmp}/p3")
        if args.against:
            against(args.against.resolve(), repeat, tmp)
            return
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
                      f"load {load:.1f}, peak memory so far {peak:.2f} GiB")
            print(f"  {name} {mask}: best {min(walls):.1f} s, median {statistics.median(walls):.1f} s")
            if args.stages:
                stages(name, scan, mask, f"{tmp}/out")


if __name__ == "__main__":
    main()
