"""Wall-clock time of `cpapfit design` (the whole chain, as a user runs it) on a synthetic subject
and on the shared fran scan (skipped without ../shared).

Usage: .venv/bin/python bench/design_time.py
"""

import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


def run(*args: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "cpapfit", *args], check=True, capture_output=True)
    return time.perf_counter() - t0


def main() -> None:
    print(f"machine: {platform.machine()}, Python {platform.python_version()}")
    with tempfile.TemporaryDirectory() as tmp:
        run("phantom", "--seed", "3", "--out", f"{tmp}/p3")
        cases = [("phantom seed 3", f"{tmp}/p3", mask) for mask in ("nasal", "oronasal")]
        if (SHARED / "fran_cyberware" / "fran.obj").exists():
            cases.append(("fran", str(SHARED / "fran_cyberware" / "fran.obj"), "nasal"))
        for name, scan, mask in cases:
            seconds = run("design", scan, "--mask", mask, "--out", f"{tmp}/out")
            print(f"cpapfit design {name} --mask {mask}: {seconds:.1f} s (process start to exit)")


if __name__ == "__main__":
    main()
