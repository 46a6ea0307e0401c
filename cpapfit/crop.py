"""Meshes cropped: to the triangles a query can reach, so that a few queries of a dense scan need
no index (r-tree, Embree scene) of all its triangles; a mesh scan to the part of it near a point."""

from dataclasses import replace

import numpy as np

from .scan import Scan


def reachable(vertices: np.ndarray, faces: np.ndarray, distance: np.ndarray, radius_mm: float) -> np.ndarray:
    """(T,) indices of the (M, 3) triangles of (N, 3) mm `vertices` whose corners all lie within
    `radius_mm` of the query, give or take the triangle's longest edge (a point in a triangle lies no
    farther than that from each corner); `distance` (N,) mm: each vertex's from the query."""
    longest = np.max([np.linalg.norm(vertices[faces[:, k]] - vertices[faces[:, k - 1]], axis=1) for k in range(3)], axis=0)
    return np.flatnonzero(distance[faces].max(axis=1) <= radius_mm + longest)


def mesh_scan_near(scan: Scan, centre: np.ndarray, radius_mm: float) -> Scan:
    """A mesh `scan` (no capture) cut to its triangles whose corners all lie within `radius_mm` of the
    (3,) mm `centre`, with their vertices (and those vertices' normals, colours and texture coordinates)."""
    kept = scan.faces[np.linalg.norm(scan.vertices - centre, axis=1)[scan.faces].max(axis=1) <= radius_mm]
    used = np.zeros(len(scan.vertices), dtype=bool)
    used[kept.ravel()] = True
    per_vertex = {name: getattr(scan, name)[used] for name in ("vertices", "normals", "colors", "uv") if getattr(scan, name) is not None}
    return replace(scan, faces=(np.cumsum(used) - 1)[kept], **per_vertex)
