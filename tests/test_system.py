"""The elastic ICP's shared factorisations: the first level factorised before any run asks, each level
factorised once for runs in step, the same bits as a run's own, a run that falls behind still
solving the system of its own level, and a failing factorisation failing every run."""

import threading
from types import SimpleNamespace

import numpy as np
from scipy.sparse import diags, random as sparse_random
from scipy.sparse.linalg import spsolve

from cpapfit.align import system
from cpapfit.align.symmetry import MirrorTerm
from cpapfit.align.cholmod import Cholesky
from cpapfit.align.system import ElasticSystem, SharedFactors, Stiffness

LEVELS = 5
WAIT_S = 60.0  # a thread stuck this long has deadlocked


def stiffness() -> Stiffness:
    """A 300-vertex system with a mirror term: two SPD CSC matrices of one pattern a level, softer each level."""
    rng = np.random.default_rng(0)
    a = sparse_random(300, 300, density=0.02, random_state=rng)
    lap = (a + a.T) + diags(np.ones(300))
    lap = (lap.T @ lap).tocsr()
    selector = (rng.random(300) < 0.1).astype(float)
    return Stiffness(1.1, lap, selector, (0.5 * lap, 0.25 * lap), 0.01, 100.0, 1.0, 0.5)


STIFFNESS = stiffness()


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
        out.append([s.solve(rhs) for s in factors.solvers(run, level)])
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
    return [Cholesky(m).solve(rhs) for m in STIFFNESS.matrices(level)]


def test_a_system_with_a_mirror_term_is_solved_in_the_planes_frame():
    """With the mirror term the displacement is, in the plane's frame, the across matrix's solution
    along the normal and the along matrix's in the plane (SuperLU's, to 1e-9 of it), each for its
    column of the right-hand side with the term's pull from the start."""
    rng = np.random.default_rng(2)
    frame = np.linalg.qr(rng.normal(size=(3, 3)))[0]  # rows: the normal, then two directions in the plane
    term = MirrorTerm(frame, STIFFNESS.mirror[0], rng.normal(size=300), STIFFNESS.mirror[1])
    rhs, start = rng.normal(size=(300, 3)), rng.normal(size=(300, 3))
    with SharedFactors(1, STIFFNESS) as factors:
        system = ElasticSystem(term, (factors, 0))
        system.at(2)
        got = system.solve(rhs, start)
    w = STIFFNESS.k * STIFFNESS.weights(2)[0]
    r, s = rhs @ frame.T, start @ frame.T
    across, along = STIFFNESS.matrices(2)
    u = spsolve(across, r[:, 0] - w * (term.across @ s[:, 0] - term.across_rhs))
    v = [spsolve(along, r[:, k] - w * (term.along @ s[:, k])) for k in (1, 2)]
    want = np.column_stack([u, *v]) @ frame
    assert np.abs(got - want).max() < 1e-9 * np.abs(want).max()


def test_level_matrices_carry_the_level_weights():
    """Level k's matrices are w I + lam_k S + mu_k L + k mu_k M, across and along, mu and lam halved a level."""
    s = STIFFNESS
    assert s.weights(3) == (100.0 / 8, 1.0 / 8)
    across, along = s.matrices(3)
    base = diags(1.1 + s.selector / 8) + 12.5 * s.lap
    assert abs(across - (base + 0.01 * 12.5 * 0.5 * s.lap)).max() < 1e-12
    assert abs(along - (base + 0.01 * 12.5 * 0.25 * s.lap)).max() < 1e-12


def test_the_first_level_is_factorised_before_any_run_asks(monkeypatch):
    """Level 0 is made as the factorisations are set up, before a run asks for it, to its own bits."""
    made = counted(monkeypatch)
    with SharedFactors(2, STIFFNESS) as factors:
        first = factors.levels[0].result(WAIT_S)
        assert made == [True] and list(factors.levels) == [0]
        rhs = np.ones(300)
        assert all(np.array_equal(s.solve(rhs), o) for s, o in zip(first, own(0, rhs)))


def test_runs_in_step_share_each_level_and_get_the_same_bits(monkeypatch):
    """Two runs that reach each level together: each level factorised once (the first new, at most one
    more, the others refactorised from a level left), every solution the bits of a run's own."""
    made = counted(monkeypatch)
    rhs = [np.random.default_rng(k).normal(size=300) for k in range(2)]
    barrier = threading.Barrier(2, timeout=WAIT_S)
    with SharedFactors(2, STIFFNESS) as factors:
        results = in_threads(*[lambda k=k: walk(factors, k, rhs[k], barrier) for k in range(2)])
    assert factors.factorised == LEVELS and len(made) == LEVELS
    assert made[0] and sum(made) <= 2
    for k in range(2):
        for level in range(LEVELS):
            assert all(np.array_equal(a, b) for a, b in zip(results[k][level], own(level, rhs[k])))
    assert factors.levels == {}


def test_a_run_far_behind_solves_its_own_levels():
    """One run walks every level before the other starts: the other finds the first level (where it
    stood) and the last (where the first run stopped) kept, and factorises those between again."""
    rhs = np.ones(300)
    with SharedFactors(2, STIFFNESS) as factors:
        first, second = walk(factors, 0, rhs), walk(factors, 1, rhs)
    assert factors.factorised == 2 * LEVELS - 2
    for level in range(LEVELS):
        assert all(np.array_equal(a, b) for a, b in zip(first[level], own(level, rhs)))
        assert all(np.array_equal(a, b) for a, b in zip(second[level], own(level, rhs)))
    assert factors.levels == {}


def test_a_run_ahead_never_takes_the_level_the_other_is_solving_at():
    """Run 0 walks every level while run 1 stands at level 1: the levels it leaves are reused for the
    next ones, never level 1, whose solvers still give run 1 its own bits; run 1 then walks on."""
    rhs = np.ones(300)

    def solved(solvers: list) -> list:
        return [s.solve(rhs) for s in solvers]

    with SharedFactors(2, STIFFNESS) as factors:
        factors.solvers(1, 0)
        standing = factors.solvers(1, 1)
        ahead = [solved(factors.solvers(0, level)) for level in range(LEVELS)]
        factors.finished(0)
        still = solved(standing)
        later = [solved(factors.solvers(1, level)) for level in range(2, LEVELS)]
        factors.finished(1)
    same = lambda got, level: all(np.array_equal(a, b) for a, b in zip(got, own(level, rhs)))  # noqa: E731
    assert all(same(got, level) for level, got in enumerate(ahead)) and same(still, 1)
    assert all(same(got, level) for level, got in zip(range(2, LEVELS), later))


def test_a_failing_factorisation_fails_every_run():
    """A factorisation that fails fails both runs, neither left waiting."""
    go = threading.Event()

    def broken(level: int):
        go.wait(WAIT_S)
        raise ArithmeticError(17)  # CHOLMOD: the column where the matrix is not positive definite

    def ask(run: int):
        if run == 1:
            go.set()
        try:
            failing.solvers(run, 0)
        except ArithmeticError as error:
            return str(error)

    with SharedFactors(2, SimpleNamespace(matrices=broken)) as failing:
        assert in_threads(lambda: ask(0), lambda: ask(1)) == ["17"] * 2
