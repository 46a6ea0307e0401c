"""The highest a surface can be above a point, along an axis: a bound that spares rays.

A ray cast along the mask axis from a point meets only triangles whose projection across the axis
holds the point, and meets each no higher up the axis than its highest corner. Over a grid of
CELL_MM squares across the axis, each square holds the highest corner of any triangle whose
projected bounding box reaches it; a point's ceiling is its square's. So a point's height over any
surface it meets along the axis is at least its own height less its ceiling (`rim.rim_in` casts
rays only from wall vertices that this bound cannot rule out).
"""

import numpy as np
import trimesh

CELL_MM = 1.0  # the grid's squares across the axis
PAD_MM = 1e-3  # boxes and heights are widened this much: the ray casts in single precision


def ceilings(points: np.ndarray, meshes: list[trimesh.Trimesh], axis: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """(P,) mm up the unit `axis`: for each of (P, 3) points, the highest any triangle of `meshes`
    that a ray along the axis from it could meet stands (-inf where none could); `plane` (2, 3) the
    unit directions across the axis."""
    flat = points @ plane.T
    lo = flat.min(axis=0) - CELL_MM
    shape = tuple(np.floor((flat.max(axis=0) - lo) / CELL_MM).astype(int) + 2)
    grid = np.full(shape, -np.inf)
    for mesh in meshes:
        _raise(grid, mesh, axis, plane, lo)
    cell = np.floor((flat - lo) / CELL_MM).astype(int)
    return grid[cell[:, 0], cell[:, 1]]


def _raise(grid: np.ndarray, mesh: trimesh.Trimesh, axis: np.ndarray, plane: np.ndarray, lo: np.ndarray) -> None:
    """Lift each square of `grid` (its corner `lo` (2,) mm across the axis) to the highest corner of
    the triangles of `mesh` whose projected bounding boxes reach it."""
    corners = [(np.asarray(mesh.vertices) @ np.vstack([plane, axis]).T)[mesh.faces[:, i]] for i in range(3)]  # (T, 3) each: across, up
    least, most = np.minimum(np.minimum(*corners[:2]), corners[2]), np.maximum(np.maximum(*corners[:2]), corners[2])
    low = np.floor((least[:, :2] - PAD_MM - lo) / CELL_MM).astype(int)  # (T, 2) first square
    high = np.floor((most[:, :2] + PAD_MM - lo) / CELL_MM).astype(int)  # (T, 2) last square
    top = most[:, 2] + PAD_MM
    size = np.array(grid.shape)
    keep = np.all((high >= 0) & (low < size), axis=1)
    low, high, top = np.clip(low[keep], 0, size - 1), np.clip(high[keep], 0, size - 1), top[keep]
    span = high - low + 1
    count = span[:, 0] * span[:, 1]
    tri = np.repeat(np.arange(len(top)), count)
    k = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
    np.maximum.at(grid, (low[tri, 0] + k // span[tri, 1], low[tri, 1] + k % span[tri, 1]), top[tri])
