"""A mesh cropped to the triangles a query can reach, so that a few queries of a dense scan need
no index (r-tree, Embree scene) of all its triangles."""

import numpy as np


def reachable(vertices: np.ndarray, faces: np.ndarray, distance: np.ndarray, radius_mm: float) -> np.ndarray:
    """(T,) indices of the (M, 3) triangles of (N, 3) mm `vertices` whose corners all lie within
    `radius_mm` of the query, give or take the triangle's longest edge (a point in a triangle lies no
    farther than that from each corner); `distance` (N,) mm: each vertex's from the query."""
    longest = np.max([np.linalg.norm(vertices[faces[:, k]] - vertices[faces[:, k - 1]], axis=1) for k in range(3)], axis=0)
    return np.flatnonzero(distance[faces].max(axis=1) <= radius_mm + longest)
