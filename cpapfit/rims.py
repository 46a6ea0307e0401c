"""Rims of a scan: the points on its edge and on the edges of its holes.

A mesh's rims are the vertices of edges used by one triangle only, vertices at one position counted
as one (a textured mesh repeats a vertex on each side of a seam of its texture map: a seam is no
rim; one real head scan had half its rim vertices on seams across the face). A depth image's are the pixels
in fewer than the six triangles of an inside pixel. A point cloud's are where a point's nearest
neighbours, seen in its tangent plane, leave a gap wider than EDGE_GAP_DEG around it (the angle
criterion of PCL's BoundaryEstimation). PCL's 90 degrees over 16 neighbours flags 26 % of the
inside of a randomly sampled surface; 120 over 24 flags 0.3 %, and 98 % of the points within half
a spacing of its edge.
"""

import numpy as np
from scipy.spatial import cKDTree

from .tangents import across

EDGE_NEIGHBOURS = 24
EDGE_GAP_DEG = 120.0


def same_position(vertices: np.ndarray) -> np.ndarray:
    """(N,) int64: one number per distinct position of (N, 3) vertices, the same for vertices at the
    same position (bit for bit)."""
    rows = np.ascontiguousarray(vertices, dtype=np.float64).view(np.dtype((np.void, 24))).ravel()
    return np.unique(rows, return_inverse=True)[1].ravel().astype(np.int64)


def boundary_vertices(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(N,) bool: vertices of (N, 3) `vertices` on an edge used by one triangle only (rims of the
    surface and its holes), vertices at one position joined."""
    out = np.zeros(len(vertices), dtype=bool)
    if len(faces) == 0:
        return out
    same = same_position(vertices)
    edges, counts = edge_uses(same[faces])
    lonely = np.zeros(int(same.max()) + 1, dtype=bool)
    lonely[edges[counts == 1].ravel()] = True
    return lonely[same]


def edge_uses(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((E, 2) the distinct edges of (M, 3) faces, each vertex pair ascending, in ascending order;
    (E,) how many triangles use each)."""
    pairs = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    n = int(faces.max()) + 1
    keys, counts = np.unique(pair_keys(pairs[:, 0], pairs[:, 1], n), return_counts=True)
    return np.stack([keys // n, keys % n], axis=1), counts


def pair_keys(a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    """(K,) int64: one number per unordered pair of indices below `n` (a[k], b[k]), the same either
    way round, ascending as the pairs (smaller first) sort."""
    return np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)


def grid_boundary(n_vertices: int, faces: np.ndarray) -> np.ndarray:
    """(N,) bool rims of a triangulated depth image: with two triangles per pixel block, a vertex
    inside the surface is used by exactly six triangles, one on a rim or hole by fewer."""
    return np.bincount(faces.ravel(), minlength=n_vertices) < 6


def cloud_boundary(points: np.ndarray, normals: np.ndarray, chunk: int = 100_000) -> np.ndarray:
    """(N,) bool: points of an (N, 3) cloud with unit normals whose EDGE_NEIGHBOURS nearest
    neighbours, seen in the point's tangent plane, leave a gap wider than EDGE_GAP_DEG around it
    (`chunk` points at a time)."""
    tree = cKDTree(points)
    k = min(EDGE_NEIGHBOURS, len(points))
    return np.concatenate([_wide_gap(points, normals, tree, np.arange(i, min(i + chunk, len(points))), k)
                           for i in range(0, len(points), chunk)])


def _wide_gap(points: np.ndarray, normals: np.ndarray, tree: cKDTree, at: np.ndarray, k: int) -> np.ndarray:
    idx = tree.query(points[at], k=k, workers=-1)[1]
    offsets = points[idx[:, 1:]] - points[at, None, :]
    u, v = across(normals[at])
    angles = np.sort(np.arctan2(np.einsum("nkj,nj->nk", offsets, v), np.einsum("nkj,nj->nk", offsets, u)), axis=1)
    gaps = np.diff(angles, axis=1, append=angles[:, :1] + 2 * np.pi)
    return gaps.max(axis=1) > np.radians(EDGE_GAP_DEG)
