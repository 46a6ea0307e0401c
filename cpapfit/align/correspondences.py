"""Correspondences of template vertices on a scan: k-d tree, or projection onto the depth grid.

Pairs are rejected when farther apart than max_distance_mm, when their normals differ by more
than max_normal_deg, or when the scan point lies on the scan's rims (`Scan.rims`: its edge and
the edges of its holes), where the nearest point is not a true correspondence.
"""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..clustering import median_edge
from ..nearest import NearestPoints
from ..rims import boundary_vertices
from ..scan import Scan


@dataclass(frozen=True)
class Target:
    """The scan as the registration sees it: vertices (N, 3) mm, unit normals oriented like the
    template's, boundary (N,) bool, and either a k-d tree or the scan's depth grid for lookups."""

    vertices: np.ndarray
    normals: np.ndarray
    boundary: np.ndarray
    tree: NearestPoints | None
    scan: Scan | None  # a capture, for projection onto its depth grid


@dataclass(frozen=True)
class Matches:
    """index: (n,) target vertex matched to each template vertex (-1: none); valid: (n,) kept pairs."""

    index: np.ndarray
    valid: np.ndarray


def make_target(scan: Scan, use_grid: bool, spacing_mm: float) -> Target:
    """The lookup structure for a scan. A mesh scan twice as coarse as `spacing_mm` is subdivided
    first (see `subdivided`), so that its nearest vertex is near its nearest surface point; its rims
    are found in a thread while its normals are made."""
    if not scan.is_capture and len(scan.faces) and median_edge(scan.vertices, scan.faces) > 2.0 * spacing_mm:
        vertices, faces = subdivided(scan.vertices, scan.faces, 1.5 * spacing_mm)
        with ThreadPoolExecutor(max_workers=1) as pool:
            rims = pool.submit(boundary_vertices, vertices, faces)
            normals = _subdivided_normals(scan, vertices, faces)
            boundary = rims.result()
    else:
        vertices, faces, normals, boundary = scan.vertices, scan.faces, scan.normals, scan.rims
    tree = None if use_grid else NearestPoints(vertices)
    return Target(vertices, normals, boundary, tree, scan if use_grid else None)


def subdivided(vertices: np.ndarray, faces: np.ndarray, edge_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle split into four (edge midpoints shared, so no cracks) as often as it takes the
    median edge to `edge_mm` or less: the surface is unchanged, its rims stay its only rims."""
    for _ in range(int(np.ceil(np.log2(median_edge(vertices, faces) / edge_mm)))):
        vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    return vertices, faces


def _subdivided_normals(scan: Scan, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Vertex normals of a subdivided scan, oriented like the original scan's."""
    normals = np.array(trimesh.Trimesh(vertices, faces, process=False).vertex_normals)
    _, idx = cKDTree(scan.vertices).query(vertices, workers=-1)  # scipy's: of the two ends an edge's midpoint lies at one distance from, `nearest.py`'s may keep the other
    flip = np.einsum("ij,ij->i", normals, scan.normals[idx]) < 0
    normals[flip] *= -1
    return normals


def oriented(target: Target, points: np.ndarray, normals: np.ndarray) -> Target:
    """The target with its normals flipped if they face into the head (a mesh wound inwards)."""
    m = lookup(target, points)
    found = m >= 0
    agree = np.einsum("ij,ij->i", target.normals[m[found]], normals[found])
    if len(agree) == 0 or np.median(agree) >= 0:
        return target
    return Target(target.vertices, -target.normals, target.boundary, target.tree, target.scan)


def lookup(target: Target, points: np.ndarray, max_distance_mm: float = np.inf) -> np.ndarray:
    """(n,) nearest target vertex of each point (-1 if none within max_distance_mm / off the grid)."""
    if target.tree is not None:
        _, index = target.tree.query(points, max_distance_mm)
        return np.where(index < len(target.vertices), index, -1)
    return nearest_on_grid(target.scan, points)


def nearest_on_grid(scan: Scan, points: np.ndarray) -> np.ndarray:
    """(n,) scan vertex of the depth pixel each point projects to (-1 outside or invalid): O(n)."""
    k = scan.intrinsics
    z = points[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.round(k.fx * points[:, 0] / z + k.cx)
        v = np.round(k.fy * points[:, 1] / z + k.cy)
    inside = (z > 0) & (u >= 0) & (u < k.width) & (v >= 0) & (v < k.height)
    out = np.full(len(points), -1, dtype=np.int64)
    out[inside] = scan.pixel_vertex[v[inside].astype(np.int64), u[inside].astype(np.int64)]
    return out


def match(target: Target, points: np.ndarray, normals: np.ndarray, max_distance_mm: float, max_normal_deg: float) -> Matches:
    """Pair (n, 3) template points with unit normals to target vertices, rejecting bad pairs."""
    index = lookup(target, points, max_distance_mm)
    found = index >= 0
    safe = np.where(found, index, 0)
    dist = np.linalg.norm(target.vertices[safe] - points, axis=1)
    cos = np.einsum("ij,ij->i", target.normals[safe], normals)
    valid = found & (dist <= max_distance_mm) & (cos >= np.cos(np.radians(max_normal_deg))) & ~target.boundary[safe]
    return Matches(index, valid)


def closest_pairs(m: Matches, points: np.ndarray, target: Target, trim: float) -> np.ndarray:
    """Indices of the valid pairs of (n, 3) `points` no farther apart than the `trim` quantile of their
    distances (a trimmed ICP's pairs)."""
    i = np.flatnonzero(m.valid)
    if len(i) == 0:
        return i
    dist = np.linalg.norm(target.vertices[m.index[i]] - points[i], axis=1)
    return i[dist <= np.quantile(dist, trim)]
