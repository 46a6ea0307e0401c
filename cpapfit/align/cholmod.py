"""CHOLMOD's supernodal sparse Cholesky factorisation, called through ctypes so that the GIL is
released while it factorises and solves: the registration's two elastic runs and the thread that
factorises their levels then work on both cores at once. The library is the one cvxopt's wheel
ships (`cvxopt.libs/libcholmod-*.so*`, CHOLMOD 3.0.6), called as cvxopt's `cholmod` module calls
it (Common's defaults, print 0, supernodal; one column solved at a time), so the factors and the
solutions are cvxopt's to the bit. cvxopt's own module holds the GIL throughout.

Each factor owns a `cholmod_common` for its analysis, numeric factorisations and freeing; each solve
makes one of its own, so two threads may solve with one factor at once.
"""

import ctypes
from ctypes import POINTER, Structure, byref, c_double, c_int, c_size_t, c_void_p
from functools import cache
from importlib import import_module
from importlib.util import find_spec
from pathlib import Path

import numpy as np
from scipy.sparse import csc_matrix

COMMON_BYTES = 1 << 16  # room for a cholmod_common (a few kB)
LONG, REAL, DOUBLE, SUPERNODAL, SOLVE_A = 2, 1, 0, 2, 0  # CHOLMOD_LONG, _REAL, _DOUBLE, _SUPERNODAL, CHOLMOD_A
COMMON_FIELDS = {  # cholmod_common's: (byte offset, type, CHOLMOD's default), read to check its layout
    "supernodal_switch": (40, c_double, 40.0), "supernodal": (48, c_int, 1), "zrelax[0]": (80, c_double, 0.8),
    "nrelax[0]": (104, c_size_t, 4), "print": (144, c_int, 3),
}


class _Sparse(Structure):
    """cholmod_sparse."""

    _fields_ = [("nrow", c_size_t), ("ncol", c_size_t), ("nzmax", c_size_t), ("p", c_void_p), ("i", c_void_p), ("nz", c_void_p),
                ("x", c_void_p), ("z", c_void_p), ("stype", c_int), ("itype", c_int), ("xtype", c_int), ("dtype", c_int),
                ("sorted", c_int), ("packed", c_int)]


class _Dense(Structure):
    """cholmod_dense."""

    _fields_ = [("nrow", c_size_t), ("ncol", c_size_t), ("nzmax", c_size_t), ("d", c_size_t), ("x", c_void_p), ("z", c_void_p),
                ("xtype", c_int), ("dtype", c_int)]


class _FactorHead(Structure):
    """The first fields of cholmod_factor."""

    _fields_ = [("n", c_size_t), ("minor", c_size_t)]


@cache
def _library() -> ctypes.CDLL:
    """cvxopt's libcholmod with the signatures of the calls made here; cvxopt's module loads it first,
    with the libraries it needs (found through the module's run path, not the library's)."""
    import_module("cvxopt.cholmod")
    found = sorted((Path(find_spec("cvxopt").origin).parents[1] / "cvxopt.libs").glob("libcholmod*.so*"))
    if not found:
        raise ImportError("CHOLMOD not found: cvxopt's wheel (cvxopt.libs/libcholmod*.so) is not installed")
    lib = ctypes.CDLL(str(found[0]))
    signatures = {
        "cholmod_l_start": ([c_void_p], c_int), "cholmod_l_finish": ([c_void_p], c_int),
        "cholmod_l_analyze_p": ([POINTER(_Sparse), c_void_p, c_void_p, c_size_t, c_void_p], c_void_p),
        "cholmod_l_factorize": ([POINTER(_Sparse), c_void_p, c_void_p], c_int),
        "cholmod_l_solve": ([c_int, c_void_p, POINTER(_Dense), c_void_p], POINTER(_Dense)),
        "cholmod_l_free_dense": ([POINTER(POINTER(_Dense)), c_void_p], c_int),
        "cholmod_l_free_factor": ([POINTER(c_void_p), c_void_p], c_int),
    }
    for name, (args, result) in signatures.items():
        getattr(lib, name).argtypes, getattr(lib, name).restype = args, result
    return lib


class _Common:
    """A started cholmod_common set as cvxopt's module sets it (print 0, supernodal); finished when dropped."""

    def __init__(self):
        self.lib = _library()
        buffer = ctypes.create_string_buffer(COMMON_BYTES)
        self.lib.cholmod_l_start(buffer)
        self.buffer = buffer
        for offset, kind, default in COMMON_FIELDS.values():
            if kind.from_buffer(buffer, offset).value != default:
                raise ImportError("this CHOLMOD's cholmod_common is not laid out as cpapfit reads it (CHOLMOD 3.0.x, cvxopt 1.3.3's wheel)")
        c_int.from_buffer(buffer, COMMON_FIELDS["supernodal"][0]).value = SUPERNODAL
        c_int.from_buffer(buffer, COMMON_FIELDS["print"][0]).value = 0

    def __del__(self):
        if hasattr(self, "buffer"):
            self.lib.cholmod_l_finish(self.buffer)


class Cholesky:
    """CHOLMOD's supernodal Cholesky factorisation P A P' = L L' of a sparse symmetric positive
    definite (n, n) matrix: its symbolic analysis made once and kept when it is refactorised for
    another matrix of the same pattern (`update`)."""

    def __init__(self, a: csc_matrix):
        self.common = _Common()
        lower = _lower(a)
        self.pattern = (lower[0], lower[1])
        self.factor = c_void_p(self.common.lib.cholmod_l_analyze_p(byref(_sparse(*lower)), None, None, 0, self.common.buffer))
        if not self.factor:
            raise MemoryError("CHOLMOD's symbolic analysis failed")
        self._numeric(lower)

    def update(self, a: csc_matrix) -> None:
        """Refactorised for `a`; ValueError if its pattern is not the pattern it was made for (CHOLMOD
        would leave out the entries outside it without a word)."""
        lower = _lower(a)
        if not all(np.array_equal(p, q) for p, q in zip(lower[:2], self.pattern)):
            raise ValueError("a factorisation refactorised for a matrix of another sparsity pattern")
        self._numeric(lower)

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """The solution of A X = rhs for an (n,) or (n, k) right-hand side, of its shape; the GIL
        released while CHOLMOD solves."""
        columns = np.array(np.asarray(rhs, dtype=np.float64).reshape(len(rhs), -1), order="F")
        common, lib = _Common(), self.common.lib
        for j in range(columns.shape[1]):
            b = _Dense(len(columns), 1, len(columns), len(columns), columns[:, j].ctypes.data, None, REAL, DOUBLE)
            x = lib.cholmod_l_solve(SOLVE_A, self.factor, byref(b), common.buffer)
            if not x:
                raise MemoryError("CHOLMOD's solve failed")
            ctypes.memmove(b.x, x.contents.x, 8 * len(columns))
            lib.cholmod_l_free_dense(byref(x), common.buffer)
        return columns.reshape(rhs.shape)

    def _numeric(self, lower: tuple) -> None:
        """The numeric factorisation of the lower triangle `lower` ((colptr, rows, values))."""
        done = self.common.lib.cholmod_l_factorize(byref(_sparse(*lower)), self.factor, self.common.buffer)
        head = _FactorHead.from_address(self.factor.value)
        if not done:
            raise MemoryError("CHOLMOD's numeric factorisation failed")
        if head.minor < head.n:
            raise ArithmeticError(f"the matrix is not positive definite (column {head.minor})")

    def __del__(self):
        if getattr(self, "factor", None):
            self.common.lib.cholmod_l_free_factor(byref(self.factor), self.common.buffer)


def _sparse(colptr: np.ndarray, rows: np.ndarray, values: np.ndarray) -> _Sparse:
    """A cholmod_sparse (lower triangle, sorted, packed) over these arrays, which the caller keeps alive."""
    n = len(colptr) - 1
    return _Sparse(n, n, len(values), colptr.ctypes.data, rows.ctypes.data, None, values.ctypes.data, None, -1, LONG, REAL, DOUBLE, 1, 1)


def _lower(a: csc_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lower triangle of a sparse (n, n) matrix (duplicates summed, explicit zeros kept in the
    pattern): its column pointers, row indices (int64) and values (float64), the triangle CHOLMOD reads."""
    a = csc_matrix(a, copy=True)
    a.sum_duplicates()  # and each column's rows sorted, as cvxopt's spmatrix holds them
    col = np.repeat(np.arange(a.shape[1]), np.diff(a.indptr))
    keep = a.indices >= col
    colptr = np.concatenate([[0], np.cumsum(np.bincount(col[keep], minlength=a.shape[1]))]).astype(np.int64)
    return colptr, a.indices[keep].astype(np.int64), np.ascontiguousarray(a.data[keep], dtype=np.float64)
