"""The elastic ICP's linear system and its factorisations, shared by the runs that build the same ones.

At membrane weight mu and landmark weight lam the system (w I + mu L + lam S + k mu M) X = B does not
change between iterations (`align/nonrigid.py`): it is factorised once per stiffness level (QDLDL's
sparse LDL^T). The two starts' runs of one registration build the same matrices at each level (the
membrane, the landmarks and the mirror pairs are the template's; only the right-hand sides differ),
so a level the other run has factorised and not yet left is solved with that factorisation, to the
same bits.
"""

import threading
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np
import qdldl
from scipy.sparse import diags

from .symmetry import MirrorTerm


class SharedFactors:
    """The factorisations at each stiffness level (0 the stiffest, counting relaxations) of one or two
    runs walking the levels in order. A level is factorised by the first run to reach it and kept
    while the other run may still reach it and needs no new solvers for it. A run moving on
    refactorises (QDLDL's numeric step, the symbolic analysis kept) the solvers of the level it
    leaves if the other run is not at it, or of one both runs have passed: at most two levels'
    solvers are alive, one per run; each level is factorised once where the runs keep within a
    level of each other, twice where one has left it before the other reaches it. `factorised`
    counts the levels factorised."""

    def __init__(self, runs: int):
        self.position = [0] * runs
        self.levels: dict[int, tuple[tuple, Future]] = {}
        self.lock = threading.Lock()
        self.factorised = 0

    def solvers(self, run: int, level: int, key: tuple, matrices) -> list:
        """The solvers of `level` for run number `run`, factorised from `matrices()` (a list of CSC
        matrices) by the first run to reach it; a run reaching it later waits for them. `key`: what
        makes the matrices (their weights), the same for every run at one level."""
        with self.lock:
            left, self.position[run] = self.position[run], level
            first = level not in self.levels
            if first:
                spare = self._free(left)
                self.levels[level] = key, Future()
                self.factorised += 1
            made_for, made = self.levels[level]
        if made_for != key:
            raise ValueError(f"stiffness level {level} asked for with {key}, factorised with {made_for}")
        if first:
            try:
                made.set_result(_factorised(matrices(), spare))
            except BaseException as error:
                made.set_exception(error)
        return made.result()

    def finished(self, run: int) -> None:
        """Run number `run` needs no more levels: those no run will reach are dropped."""
        with self.lock:
            self.position[run] = np.inf
            for level in [k for k in self.levels if k < min(self.position)]:
                del self.levels[level]

    def _free(self, left: int) -> list | None:
        """Factorised solvers no run is at, taken out of their level (lock held): the level `left`
        (the one the requesting run leaves), or one every run has passed; None if there are none."""
        for level in sorted(self.levels):
            made = self.levels[level][1]
            if level not in self.position and (level == left or level < min(self.position)) and made.done() and made.exception() is None:
                return self.levels.pop(level)[1].result()
        return None


def _factorised(matrices: list, spare: list | None) -> list:
    """QDLDL solvers of the CSC `matrices`: `spare`'s (of matrices of the same patterns) refactorised, or new."""
    if spare is None:
        return [qdldl.Solver(m) for m in matrices]
    for solver, m in zip(spare, matrices):
        solver.update(m)
    return spare


class ElasticSystem:
    """(w I + mu L + lam S + k mu M) X = B for (n, 3) right-hand sides, M the mirror term (if any), k its
    weight per unit of membrane, at the stiffness level set by `at` (level 0 at mu, lam to begin).
    shared: the factorisations shared with the other run, and this run's number. Without a mirror
    term one matrix serves x, y and z; with one, the system is solved in the plane's frame, one
    matrix across it, one along."""

    def __init__(self, w_data: float, lap, selector: np.ndarray, mirror: MirrorTerm | None, k: float, shared: tuple[SharedFactors, int],
                 mu: float, lam: float):
        self.w_data, self.lap, self.selector, self.mirror, self.k = w_data, lap, selector, mirror, k
        self.factors, self.run = shared
        self.at(0, mu, lam)

    def at(self, level: int, mu: float, lam: float) -> None:
        """Stiffness level `level`: membrane weight mu, landmark weight lam (factorised by the first run to reach it)."""
        self.weight = self.k * mu
        key = (self.w_data, mu, lam, self.weight, self.mirror is None)
        self.solvers = self.factors.solvers(self.run, level, key, lambda: self._matrices(mu, lam, self.weight))

    def _matrices(self, mu: float, lam: float, weight: float) -> list:
        """The CSC matrices at (mu, lam) and mirror weight `weight`: one, or across and along the plane."""
        base = diags(self.w_data + lam * self.selector) + mu * self.lap
        matrices = [base] if self.mirror is None else [base + weight * self.mirror.across, base + weight * self.mirror.along]
        return [m.tocsc() for m in matrices]

    def solve(self, rhs: np.ndarray, start: np.ndarray) -> np.ndarray:
        """The displacement (n, 3) mm from the (n, 3) `start` for right-hand side `rhs`: x, y and z
        solved side by side (QDLDL releases the GIL; each column is independent)."""
        if self.mirror is None:
            return _columns(rhs, [self.solvers[0]] * 3)
        m, w = self.mirror, self.weight
        r, s = rhs @ m.frame.T, start @ m.frame.T  # in the plane's frame
        r[:, 0] -= w * (m.across @ s[:, 0] - m.across_rhs)
        r[:, 1:] -= w * (m.along @ s[:, 1:])
        return _columns(r, [self.solvers[0], self.solvers[1], self.solvers[1]]) @ m.frame


def _columns(rhs: np.ndarray, solvers: list) -> np.ndarray:
    """(n, 3): each column of `rhs` solved by its solver, in threads."""
    columns = [np.ascontiguousarray(rhs[:, k]) for k in range(3)]
    with ThreadPoolExecutor(max_workers=3) as pool:
        return np.column_stack(list(pool.map(lambda sc: sc[0].solve(sc[1]), zip(solvers, columns))))
