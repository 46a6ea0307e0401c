"""The nearest of a fixed set of 3-D points to each of many others: pykdtree's k-d tree, its queries
spread over the cores by OpenMP with the GIL released. On the registration's queries (the template's
28 881 vertices against a scan's 229 000) it answers in two thirds of scipy's `cKDTree` time on
all cores, and in under half with two threads querying at once (the registration's two starts),
with the same neighbours and distances (`bench/RESULTS.md` section 2). Of points at one distance
from a query (a subdivided mesh's edge midpoint from the edge's ends) it may keep another than
scipy's would.
"""

import numpy as np
from pykdtree.kdtree import KDTree


class NearestPoints:
    """A k-d tree of (N, 3) `points` (mm)."""

    def __init__(self, points: np.ndarray):
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        self._tree = KDTree(self.points) if len(self.points) else None

    def query(self, points: np.ndarray, bound: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """((K,) distance mm, (K,) int64 index) of the nearest point to each of (K, 3) `points` nearer
        than `bound` mm; where there is none, the distance is inf and the index N (as scipy's)."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if self._tree is None or len(points) == 0:
            return np.full(len(points), np.inf), np.full(len(points), len(self.points), dtype=np.int64)
        dist, index = self._tree.query(points, distance_upper_bound=None if np.isinf(bound) else float(bound))
        return dist, index.astype(np.int64)
