"""CHOLMOD through ctypes (`align/cholmod.py`): its factors and solutions those of cvxopt's own
module to the bit, refactorised for a matrix of the same pattern, solving from two threads at once
with one factor, and refusing a matrix that is not positive definite or of another pattern."""

import threading

import numpy as np
import pytest
from cvxopt import cholmod as cvxopt_cholmod, matrix, spmatrix
from scipy.sparse import csc_matrix, diags, random as sparse_random
from scipy.sparse.linalg import spsolve

from cpapfit.align.cholmod import Cholesky

N = 2000


def spd(seed: int, scale: float = 1.0) -> csc_matrix:
    """An (N, N) sparse symmetric positive definite matrix, the pattern the same for every seed and scale."""
    pattern = sparse_random(N, N, density=0.002, random_state=np.random.default_rng(0))
    values = pattern.copy()
    values.data = np.random.default_rng(seed).uniform(0.5, 1.5, len(values.data))
    a = values + values.T
    return csc_matrix(a @ a.T * scale + diags(np.full(N, 3.0)))


def cvxopt_solution(a: csc_matrix, rhs: np.ndarray) -> np.ndarray:
    """cvxopt's own cholmod module's solution of a X = rhs (its supernodal default)."""
    lower = a.tocoo()
    keep = lower.row >= lower.col
    m = spmatrix(matrix(lower.data[keep]), matrix(lower.row[keep].astype(np.int_)), matrix(lower.col[keep].astype(np.int_)), size=a.shape)
    factor = cvxopt_cholmod.symbolic(m)
    cvxopt_cholmod.numeric(m, factor)
    x = matrix(np.asarray(rhs, dtype=np.float64).reshape(N, -1))
    cvxopt_cholmod.solve(factor, x)
    return np.array(x).reshape(rhs.shape)


def test_the_solutions_are_cvxopts_to_the_bit_and_solve_the_system():
    """One and three right-hand sides: the same bits as cvxopt's module, and a X - rhs within 1e-9 of
    rhs (SuperLU's solution within 1e-9 of the solution)."""
    rhs = np.random.default_rng(1).normal(size=(N, 3))
    a = spd(1)
    solver = Cholesky(a)
    for b in (rhs, rhs[:, 0]):
        x = solver.solve(b)
        assert x.shape == b.shape
        assert np.array_equal(x, cvxopt_solution(a, b))
        assert np.abs(a @ x - b).max() < 1e-9 * np.abs(b).max()
        assert np.abs(x - spsolve(a, b)).max() < 1e-9 * np.abs(x).max()


def test_a_refactorised_factor_solves_the_new_matrix_to_the_bits_of_a_new_one():
    rhs = np.random.default_rng(2).normal(size=(N, 3))
    solver, b = Cholesky(spd(1)), spd(2, scale=0.25)
    solver.update(b)
    assert np.array_equal(solver.solve(rhs), Cholesky(b).solve(rhs))
    assert np.abs(b @ solver.solve(rhs) - rhs).max() < 1e-9 * np.abs(rhs).max()


def test_two_threads_solving_with_one_factor_get_the_answers_of_one():
    a = spd(3)
    solver = Cholesky(a)
    rhs = [np.random.default_rng(seed).normal(size=(N, 2)) for seed in range(8)]
    alone = [solver.solve(b) for b in rhs]
    both: list = [None] * len(rhs)

    def solve(first: int) -> None:
        for _ in range(20):
            for k in range(first, len(rhs), 2):
                both[k] = solver.solve(rhs[k])

    threads = [threading.Thread(target=solve, args=(k,)) for k in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60.0)
    assert all(np.array_equal(x, y) for x, y in zip(alone, both))


def test_a_matrix_not_positive_definite_or_of_another_pattern_is_refused():
    indefinite = spd(4) - diags(np.full(N, 1e3))
    with pytest.raises(ArithmeticError, match="not positive definite"):
        Cholesky(indefinite)
    with pytest.raises(ValueError, match="another sparsity pattern"):
        Cholesky(diags(np.full(N, 2.0)).tocsc()).update(spd(1))
