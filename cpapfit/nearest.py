"""The nearest of a fixed set of 3-D points to each of many others: pykdtree's k-d tree, its queries
spread over the cores by OpenMP with the GIL released. On the registration's queries (the template's
28 881 vertices against a scan's 229 291) it answers in about three quarters of scipy's `cKDTree`
time on both cores, and in two thirds with two threads querying at once (the registration's two
starts), with the same neighbours and distances (`bench/RESULTS.md` section 2). Of points at one
distance from a query (a subdivided mesh's edge midpoint from the edge's ends) it may keep another
than scipy's would.

A thread that has queried keeps OpenMP's idle threads for the rest of the process, and a fork copies
only the calling thread: in a forked child the thread that forked runs OpenMP on one thread
(`_one_thread`), whose next parallel region would otherwise wait for ever for threads the child
does not have; threads started in the child begin OpenMP afresh, on every core.
"""

import ctypes
import os
from pathlib import Path

import numpy as np
from pykdtree.kdtree import KDTree


def _libgomps() -> list[ctypes.CDLL]:
    """The OpenMP runtimes (libgomp) this process has loaded, pykdtree's among them (Linux's
    /proc/self/maps; none where it cannot tell)."""
    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return []
    paths = sorted({line.split(maxsplit=5)[-1] for line in maps.splitlines() if "libgomp" in line.rsplit("/", 1)[-1]})
    return [ctypes.CDLL(path) for path in paths]


_OPENMP = _libgomps()  # resolved here, not in a forked child, where loading a library could wait on a lock


def _one_thread() -> None:
    """In a forked child: OpenMP on one thread in the thread that forked (the module docstring)."""
    for lib in _OPENMP:
        lib.omp_set_num_threads(1)


os.register_at_fork(after_in_child=_one_thread)


class NearestPoints:
    """A k-d tree of (N, 3) `points` (mm)."""

    def __init__(self, points: np.ndarray):
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        self._tree = KDTree(self.points) if len(self.points) else None

    def query(self, points: np.ndarray, bound: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """((K,) distance mm, (K,) int64 index) of the nearest point to each of (K, 3) `points` nearer
        than `bound` mm; where there is none (or `bound` is not over 0), the distance is inf and the
        index N, as scipy's. ValueError for points that are not (K, 3) or not finite."""
        points = np.ascontiguousarray(points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"query points of shape {points.shape}, not (K, 3)")
        if not np.isfinite(points).all():
            raise ValueError("query points that are not finite")
        n = len(self.points)
        if self._tree is None or len(points) == 0 or not bound > 0:
            return np.full(len(points), np.inf), np.full(len(points), n, dtype=np.int64)
        dist, index = self._tree.query(points, distance_upper_bound=None if np.isinf(bound) else float(bound))
        return dist, index.astype(np.int64)
