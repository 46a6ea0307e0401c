"""The elastic ICP's shared factorisations: each level factorised once for runs in step, the same bits
as a run's own, and a run that falls behind still solving the system of its own level."""

import threading

import numpy as np
import qdldl
from scipy.sparse import diags, random as sparse_random

from cpapfit.align import system
from cpapfit.align.system import SharedFactors

LEVELS = 4


def matrices(level: int) -> list:
    """Two SPD CSC matrices of one pattern (across, along), softer each level."""
    rng = np.random.default_rng(0)
    a = sparse_random(300, 300, density=0.02, random_state=rng)
    lap = (a + a.T) + diags(np.ones(300))
    lap = lap.T @ lap
    return [(diags(np.full(300, 1.1)) + 0.5 ** level * scale * lap).tocsc() for scale in (100.0, 50.0)]


def counted(monkeypatch) -> list:
    """The levels' factorisations: (made new?) for each."""
    made, real = [], system._factorised
    monkeypatch.setattr(system, "_factorised", lambda m, spare: made.append(spare is None) or real(m, spare))
    return made


def walk(factors: SharedFactors, run: int, rhs: np.ndarray, barrier: threading.Barrier | None = None) -> list:
    """Run `run`'s solutions of `rhs` at each level."""
    out = []
    for level in range(LEVELS):
        if barrier is not None:
            barrier.wait()
        out.append([s.solve(rhs) for s in factors.solvers(run, level, lambda: matrices(level))])
    factors.finished(run)
    return out


def test_runs_in_step_share_each_level_and_get_the_same_bits(monkeypatch):
    made = counted(monkeypatch)
    factors, rhs = SharedFactors(2), [np.random.default_rng(k).normal(size=300) for k in range(2)]
    barrier, results = threading.Barrier(2), [None, None]
    threads = [threading.Thread(target=lambda k=k: results.__setitem__(k, walk(factors, k, rhs[k], barrier))) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(made) == LEVELS and made[:2] == [True, True] and not any(made[2:])  # two new, then refactorised
    for k in range(2):
        for level in range(LEVELS):
            own = [qdldl.Solver(m).solve(rhs[k]) for m in matrices(level)]
            assert all(np.array_equal(a, b) for a, b in zip(results[k][level], own))
    assert factors.levels == {}


def test_a_run_far_behind_solves_its_own_levels(monkeypatch):
    """One run walks every level before the other starts: the other finds the first level (where it
    stood) and the last (where the first run stopped) kept, and factorises those between itself."""
    made = counted(monkeypatch)
    factors, rhs = SharedFactors(2), np.ones(300)
    first, second = walk(factors, 0, rhs), walk(factors, 1, rhs)
    assert made == [True, True] + [False] * (LEVELS - 2) + [False] * (LEVELS - 2)
    for level in range(LEVELS):
        own = [qdldl.Solver(m).solve(rhs) for m in matrices(level)]
        assert all(np.array_equal(a, b) for a, b in zip(first[level], own))
        assert all(np.array_equal(a, b) for a, b in zip(second[level], own))
