"""The elastic ICP's shared factorisations: each level factorised once for runs in step, the same bits
as a run's own, a run that falls behind still solving the system of its own level, and a run never
solving a system made with other weights."""

import threading

import numpy as np
import pytest
import qdldl
from scipy.sparse import diags, random as sparse_random

from cpapfit.align import system
from cpapfit.align.system import SharedFactors

LEVELS = 4
WAIT_S = 60.0  # a thread stuck this long has deadlocked


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
        out.append([s.solve(rhs) for s in factors.solvers(run, level, (0.5 ** level,), lambda: matrices(level))])
    factors.finished(run)
    return out


def in_threads(*jobs) -> list:
    """Each job's result, the jobs run in threads of their own."""
    results = [None] * len(jobs)
    threads = [threading.Thread(target=lambda k=k: results.__setitem__(k, jobs[k]())) for k in range(len(jobs))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(WAIT_S)
    assert not any(t.is_alive() for t in threads)
    return results


def own(level: int, rhs: np.ndarray) -> list:
    """The solutions of a run factorising its own matrices."""
    return [qdldl.Solver(m).solve(rhs) for m in matrices(level)]


def test_runs_in_step_share_each_level_and_get_the_same_bits(monkeypatch):
    """Two runs that reach each level together: each level factorised once (the first two new, the
    others refactorised from a level both have left), every solution the bits of a run's own."""
    made = counted(monkeypatch)
    factors, rhs = SharedFactors(2), [np.random.default_rng(k).normal(size=300) for k in range(2)]
    barrier = threading.Barrier(2, timeout=WAIT_S)
    results = in_threads(*[lambda k=k: walk(factors, k, rhs[k], barrier) for k in range(2)])
    assert made == [True, True] + [False] * (LEVELS - 2) and factors.factorised == LEVELS
    for k in range(2):
        for level in range(LEVELS):
            assert all(np.array_equal(a, b) for a, b in zip(results[k][level], own(level, rhs[k])))
    assert factors.levels == {}


def test_a_run_far_behind_solves_its_own_levels(monkeypatch):
    """One run walks every level before the other starts: the other finds the first level (where it
    stood) and the last (where the first run stopped) kept, and factorises those between itself."""
    made = counted(monkeypatch)
    factors, rhs = SharedFactors(2), np.ones(300)
    first, second = walk(factors, 0, rhs), walk(factors, 1, rhs)
    assert made == [True, True] + [False] * (LEVELS - 2) + [False] * (LEVELS - 2)
    for level in range(LEVELS):
        assert all(np.array_equal(a, b) for a, b in zip(first[level], own(level, rhs)))
        assert all(np.array_equal(a, b) for a, b in zip(second[level], own(level, rhs)))
    assert factors.levels == {}


def test_a_level_asked_for_with_other_weights_or_failing_to_factorise_is_an_error():
    """A run asking for a level factorised with other weights is refused, not handed another system;
    a factorisation that fails fails both runs, neither left waiting."""
    factors = SharedFactors(2)
    factors.solvers(0, 0, (1.0,), lambda: matrices(0))
    with pytest.raises(ValueError, match="factorised with"):
        factors.solvers(1, 0, (2.0,), lambda: matrices(0))
    failing, go = SharedFactors(2), threading.Event()

    def broken():
        go.wait(WAIT_S)
        raise np.linalg.LinAlgError("not quasi-definite")

    def ask(run: int):
        if run == 1:
            go.set()
        try:
            failing.solvers(run, 0, (1.0,), broken)
        except np.linalg.LinAlgError as error:
            return str(error)

    assert in_threads(lambda: ask(0), lambda: ask(1)) == ["not quasi-definite"] * 2
