"""Correspondences of template vertices on a scan: k-d tree, or projection onto the depth grid.

Pairs are rejected when farther apart than max_distance_mm, when their normals differ by more
than max_normal_deg, or when the scan point lies on the scan's boundary (its rim and the rims
of its holes), where the nearest point is not a true correspondence. A point cloud's boundary
is where a point's nearest neighbours, seen in its tangent plane, leave a gap wider than
EDGE_GAP_DEG around it (the angle criterion of PCL's BoundaryEstimation). PCL's 90 degrees over 16
neighbours flags 26 % of the inside of a randomly sampled surface; 120 over 24 flags 0.3 %, and
98 % of the points within half a spacing of its edge.
"""

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..scan import Scan


EDGE_NEIGHBOURS = 24
EDGE_GAP_DEG = 120.0


@dataclass(frozen=True)
class Target:
    """The scan as the registration sees it: vertices (N, 3) mm, unit normals oriented like the
    template's, boundary (N,) bool, and either a k-d tree or the scan's depth grid for lookups."""

    vertices: np.ndarray
    normals: np.ndarray
    boundary: np.ndarray
    tree: cKDTree | None
    scan: Scan | None  # a capture, for projection onto its depth grid


@dataclass(frozen=True)
class Matches:
    """index: (n,) target vertex matched to each template vertex (-1: none); valid: (n,) kept pairs."""

    index: np.ndarray
    valid: np.ndarray


def boundary_vertices(n_vertices: int, faces: np.ndarray) -> np.ndarray:
    """(N,) bool: vertices on an edge used by one triangle only (rims of the surface and its holes)."""
    out = np.zeros(n_vertices, dtype=bool)
    if len(faces) == 0:
        return out
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    keys, counts = np.unique(edges[:, 0] * n_vertices + edges[:, 1], return_counts=True)
    lonely = keys[counts == 1]
    out[lonely // n_vertices] = True
    out[lonely % n_vertices] = True
    return out


def make_target(scan: Scan, use_grid: bool, spacing_mm: float) -> Target:
    """The lookup structure for a scan. A mesh scan twice as coarse as `spacing_mm` is subdivided
    first (see `subdivided`), so that its nearest vertex is near its nearest surface point."""
    vertices, faces, normals = scan.vertices, scan.faces, scan.normals
    if not scan.is_capture and len(faces) and _median_edge(vertices, faces) > 2.0 * spacing_mm:
        vertices, faces = subdivided(vertices, faces, 1.5 * spacing_mm)
        normals = _subdivided_normals(scan, vertices, faces)
    tree = None if use_grid else cKDTree(vertices, balanced_tree=False, compact_nodes=False)  # the quicker queries
    boundary = scan_boundary(scan) if scan.is_capture or scan.is_point_cloud else boundary_vertices(len(vertices), faces)
    return Target(vertices, normals, boundary, tree, scan if use_grid else None)


def subdivided(vertices: np.ndarray, faces: np.ndarray, edge_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Every triangle split into four (edge midpoints shared, so no cracks) as often as it takes the
    median edge to `edge_mm` or less: the surface is unchanged, its rims stay its only rims."""
    for _ in range(int(np.ceil(np.log2(_median_edge(vertices, faces) / edge_mm)))):
        vertices, faces = trimesh.remesh.subdivide(vertices, faces)
    return vertices, faces


def scan_boundary(scan: Scan) -> np.ndarray:
    """(N,) bool: the scan's points on its rims and the rims of its holes (a capture's, a mesh's or
    a point cloud's)."""
    if scan.is_capture:
        return grid_boundary(scan)
    if scan.is_point_cloud:
        return cloud_boundary(scan.vertices, scan.normals)
    return boundary_vertices(len(scan.vertices), scan.faces)


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
    n = normals[at]
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    u = np.cross(n, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(n, u)
    angles = np.sort(np.arctan2(np.einsum("nkj,nj->nk", offsets, v), np.einsum("nkj,nj->nk", offsets, u)), axis=1)
    gaps = np.diff(angles, axis=1, append=angles[:, :1] + 2 * np.pi)
    return gaps.max(axis=1) > np.radians(EDGE_GAP_DEG)


def grid_boundary(scan: Scan) -> np.ndarray:
    """(N,) bool rims of a triangulated depth image: with two triangles per pixel block, a vertex
    inside the surface is used by exactly six triangles, one on a rim or hole by fewer."""
    return np.bincount(scan.faces.ravel(), minlength=len(scan.vertices)) < 6


def _median_edge(vertices: np.ndarray, faces: np.ndarray) -> float:
    return float(np.median(np.linalg.norm(vertices[faces[:, 0]] - vertices[faces[:, 1]], axis=1)))


def _subdivided_normals(scan: Scan, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Vertex normals of a subdivided scan, oriented like the original scan's."""
    normals = np.array(trimesh.Trimesh(vertices, faces, process=False).vertex_normals)
    _, idx = cKDTree(scan.vertices).query(vertices)
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
        _, index = target.tree.query(points, distance_upper_bound=max_distance_mm, workers=-1)
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
