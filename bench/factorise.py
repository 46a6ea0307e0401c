"""The registration's sparse factorisations, by each solver at hand, on the template's own level
matrices: what `align/system.py` factorises (CHOLMOD, `align/cholmod.py`) against the others tried.

The matrices: the 28 881-vertex template's membrane Laplacian, its 468 landmark vertices pulled at
the detected landmarks' tenth of the paper's weight, its mirror pairs across and along a plane
(`nonrigid._stiffness`), levels 0 and 1 (the pattern is the same at every level). Each solver:
factorised at level 0 (its symbolic analysis included), refactorised at level 1 where it can keep
its analysis (else factorised afresh), and three right-hand sides solved; CPU seconds of this
process, the best of `--repeat` rounds, and the largest residual |A x - b| / |b|. Solvers not
installed are skipped with a line saying so (QDLDL: `pip install qdldl`; feral: `pip install
feral-solver`).

Usage: .venv/bin/python bench/factorise.py [--repeat 5]
"""

import argparse
import platform
import time

from cpapfit import __version__  # first: it sets OpenBLAS to one thread, as `cpapfit register` runs, before numpy loads it

import numpy as np
from scipy.sparse.linalg import splu

from cpapfit.align.laplacian import laplacian
from cpapfit.align.nonrigid import NonrigidParams, _stiffness
from cpapfit.align.symmetry import mirror_pairs
from cpapfit.align.cholmod import Cholesky
from cpapfit.template import N_LANDMARKS, load_template


class SuperLU:
    """scipy's SuperLU (no kept analysis: each factorisation is whole)."""

    def __init__(self, a):
        self.lu = splu(a.tocsc())

    def update(self, a):
        self.lu = splu(a.tocsc())

    def solve(self, rhs):
        return self.lu.solve(rhs)


def qdldl_solver():
    """QDLDL (simplicial LDL^T, analysis kept), one right-hand side a call."""
    import qdldl

    class QDLDL:
        def __init__(self, a):
            self.s = qdldl.Solver(a.tocsc())

        def update(self, a):
            self.s.update(a.tocsc())

        def solve(self, rhs):
            return np.column_stack([self.s.solve(np.ascontiguousarray(c)) for c in rhs.T])

    return QDLDL


def feral_solver():
    """feral (supernodal LDL^T in Rust, analysis kept; its solver is bound to the thread that made it)."""
    import feral

    class Feral:
        def __init__(self, a):
            self.s = feral.Solver()
            self.s.factor(feral.from_scipy(a.tocsc()))

        def update(self, a):
            self.s.factor(feral.from_scipy(a.tocsc()))

        def solve(self, rhs):
            return np.column_stack([np.asarray(self.s.solve(np.ascontiguousarray(c))) for c in rhs.T])

    return Feral


def timed(solver, levels: list, rhs: np.ndarray) -> tuple[float, float, float, float]:
    """(factorise, refactorise, solve three) CPU s and the worst relative residual."""
    t0 = time.process_time()
    s = solver(levels[0])
    t1 = time.process_time()
    s.update(levels[1])
    t2 = time.process_time()
    x = s.solve(rhs)
    t3 = time.process_time()
    residual = float(np.abs(levels[1] @ x - rhs).max() / np.abs(rhs).max())
    return t1 - t0, t2 - t1, t3 - t2, residual


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    print(f"cpapfit {__version__}, Python {platform.python_version()}, {platform.machine()}; CPU seconds, best of {args.repeat}")
    template = load_template()
    params = NonrigidParams()
    stiffness = _stiffness(laplacian(template.vertices, template.faces), mirror_pairs(template.mirror), np.arange(N_LANDMARKS),
                           params.detected_landmark_factor, params)
    levels = [stiffness.matrices(level) for level in (0, 1)]
    rhs = np.random.default_rng(0).normal(size=(len(template.vertices), 3))
    solvers = {"CHOLMOD (cpapfit's)": lambda: Cholesky, "SuperLU (scipy)": lambda: SuperLU, "QDLDL": qdldl_solver,
               "feral": feral_solver}
    print("| solver | matrix | factorise (s) | refactorise (s) | solve x, y, z (s) | residual |")
    print("|---|---|---|---|---|---|")
    for name, make in solvers.items():
        try:
            solver = make()
        except ImportError:
            print(f"| {name} | not installed | | | | |")
            continue
        for k, which in enumerate(("across", "along")):
            rounds = [timed(solver, [levels[0][k], levels[1][k]], rhs) for _ in range(args.repeat)]
            best = np.min([r[:3] for r in rounds], axis=0)
            print(f"| {name} | {which} | {best[0]:.3f} | {best[1]:.3f} | {best[2]:.4f} | {max(r[3] for r in rounds):.0e} |")


if __name__ == "__main__":
    main()
