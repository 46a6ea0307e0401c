"""The elastic ICP's linear system at each stiffness level, factorised ahead of the runs that solve it.

At membrane weight mu and landmark weight lam the system (w I + mu L + lam S + k mu M) X = B does not
change between iterations (`align/nonrigid.py`): it is factorised once per stiffness level
(CHOLMOD's Cholesky factorisation, `Cholesky`). Its matrices are the template's (the membrane, the
landmarks it pulls, the mirror pairs) and the level's weights, known before the scan is looked at:
a thread of their own factorises the first level while the scan is made a target and the runs'
starts are fitted, and each next level when the first run reaches it. The two starts' runs of one
registration solve the same matrices at each level (only the right-hand sides differ) with the
same factorisations, to the same bits as their own.
"""

import threading
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix, diags

from .cholmod import Cholesky
from .symmetry import MirrorTerm


@dataclass(frozen=True, eq=False)
class Stiffness:
    """The system's matrices and weights at each level: w_data the data terms' weight per vertex, lap
    the (n, n) membrane Laplacian, selector (n,) 1 at the landmarks pulled, mirror (across, along)
    (n, n) the mirror pairs' matrices (`symmetry.MirrorPairs`; None: no mirror term) at k per unit of
    membrane; level 0 at (membrane, landmark), each next level both times relax."""

    w_data: float
    lap: csr_matrix
    selector: np.ndarray
    mirror: tuple[csr_matrix, csr_matrix] | None
    k: float
    membrane: float
    landmark: float
    relax: float

    def weights(self, level: int) -> tuple[float, float]:
        """(membrane weight mu, landmark weight lam) at `level`: relaxed once a level."""
        mu, lam = self.membrane, self.landmark
        for _ in range(level):
            mu, lam = mu * self.relax, lam * self.relax
        return mu, lam

    def matrices(self, level: int) -> list:
        """The CSC matrices at `level`: one, or with the mirror term across and along its plane."""
        mu, lam = self.weights(level)
        base = diags(self.w_data + lam * self.selector) + mu * self.lap
        matrices = [base] if self.mirror is None else [base + self.k * mu * m for m in self.mirror]
        return [m.tocsc() for m in matrices]


class SharedFactors:
    """The factorisations at each stiffness level (0 the stiffest) of one or two runs
    walking them in order, made in a thread of their own: the first at once, each other when the
    first run reaches it. A factorisation reuses (`Cholesky.update`: the numeric step, the symbolic
    analysis kept) the solvers of a level no run is at and some run has passed, first one every run
    has passed: a run far behind the other factorises the levels between again. `factorised` counts
    the levels queued for factorising. Used as a context manager: on leaving it the thread stops (a
    level it has begun is finished and dropped)."""

    def __init__(self, runs: int, stiffness: Stiffness):
        self.stiffness = stiffness
        self.position = [0] * runs
        self.levels: dict[int, Future] = {}
        self.lock = threading.Lock()
        self.factorised = 0
        self.pool = ThreadPoolExecutor(max_workers=1)
        with self.lock:
            self._queue(0)

    def __enter__(self) -> "SharedFactors":
        return self

    def __exit__(self, *exc) -> None:
        self.pool.shutdown(wait=False, cancel_futures=True)
        self.levels.clear()

    def solvers(self, run: int, level: int) -> list:
        """The solvers of `level` for run number `run` (waiting for them if they are being made)."""
        with self.lock:
            self.position[run] = level
            self._queue(level)
            made = self.levels[level]
        return made.result()

    def finished(self, run: int) -> None:
        """Run number `run` needs no more levels: those no run will reach are dropped."""
        with self.lock:
            self.position[run] = np.inf
            for level in [k for k in self.levels if k < min(self.position)]:
                self.levels.pop(level).cancel()

    def _queue(self, level: int) -> None:
        """`level` queued for factorising unless made or queued (lock held)."""
        if level not in self.levels:
            self.levels[level] = self.pool.submit(self._factorise, level)
            self.factorised += 1

    def _factorise(self, level: int) -> list:
        """The solvers of `level`, refactorised from a spare level's where there is one."""
        with self.lock:
            spare = self._spare()
        return _factorised(self.stiffness.matrices(level), spare)

    def _spare(self) -> list | None:
        """Made solvers of a level no run is at and some run has passed, taken out of it (lock held):
        one every run has passed first; None if there are none."""
        passed = [k for k in sorted(self.levels) if k not in self.position and k < max(self.position) and self.levels[k].done()
                  and self.levels[k].exception() is None]
        if not passed:
            return None
        return self.levels.pop(min(passed, key=lambda k: k >= min(self.position))).result()


def _factorised(matrices: list, spare: list | None) -> list:
    """Factorisations (`Cholesky`) of the CSC `matrices`: `spare`'s (of matrices of the same patterns)
    refactorised, or new."""
    if spare is None:
        return [Cholesky(m) for m in matrices]
    for solver, m in zip(spare, matrices):
        solver.update(m)
    return spare


class ElasticSystem:
    """(w I + mu L + lam S + k mu M) X = B for (n, 3) right-hand sides, M the mirror term (if any), at
    the stiffness level set by `at` (level 0 to begin). shared: the factorisations shared with the
    other run, and this run's number. Without a mirror term one matrix serves x, y and z; with one,
    the system is solved in the plane's frame, one matrix across it, one along."""

    def __init__(self, mirror: MirrorTerm | None, shared: tuple[SharedFactors, int]):
        self.mirror = mirror
        self.factors, self.run = shared
        self.at(0)

    def at(self, level: int) -> None:
        """Stiffness level `level` (its solvers waited for if they are being made)."""
        self.weight = self.factors.stiffness.k * self.factors.stiffness.weights(level)[0]
        self.solvers = self.factors.solvers(self.run, level)
        if len(self.solvers) != (1 if self.mirror is None else 2):
            raise ValueError(f"{len(self.solvers)} matrices factorised for a system {'without' if self.mirror is None else 'with'} a mirror term")

    def solve(self, rhs: np.ndarray, start: np.ndarray) -> np.ndarray:
        """The displacement (n, 3) mm from the (n, 3) `start` for the (n, 3) right-hand side `rhs`: the
        columns that share a matrix solved in one call (x, y and z; with the mirror term the one
        across the plane, then the two along it)."""
        if self.mirror is None:
            return self.solvers[0].solve(rhs)
        m, w = self.mirror, self.weight
        r, s = rhs @ m.frame.T, start @ m.frame.T  # in the plane's frame
        r[:, 0] -= w * (m.across @ s[:, 0] - m.across_rhs)
        r[:, 1:] -= w * (m.along @ s[:, 1:])
        return np.hstack([self.solvers[0].solve(r[:, :1]), self.solvers[1].solve(r[:, 1:])]) @ m.frame
