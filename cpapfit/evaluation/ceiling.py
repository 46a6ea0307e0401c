"""The highest a surface can be above a point, along an axis: a bound that spares rays.

A ray cast along the mask axis from a point meets only triangles whose projection across the axis
holds the point, and meets each no higher up the axis than its highest corner. Over a grid of
CELL_MM squares across the axis, each square holds the highest corner of any triangle whose
projected bounding box reaches it; a point's ceiling is its square's. So a point's height over any
surface it meets along the axis is at least its own height less its ceiling (`rim.rim_in` casts
rays from the wall higher than its lowest millimetre only where this bound cannot rule out that
they touch first). A mesh's grid is kept for the next
call about the same axis (the last four): a stock cushion is seated at many places on one face.
"""

import numpy as np
import trimesh

from ..kept import Kept

CELL_MM = 1.0  # the grid's squares across the axis
PAD_MM = 1e-3  # boxes and heights are widened this much: the ray casts in single precision
_GRIDS = Kept(4)


def ceilings(flat: np.ndarray, meshes: list[trimesh.Trimesh], axis: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """(P,) mm up the unit `axis`: for each of P points, at (P, 2) mm `flat` across it (points @
    plane.T), the highest any triangle of `meshes` that a ray along the axis from it could meet
    stands (-inf where none could); `plane` (2, 3) the unit directions across the axis."""
    out = np.full(len(flat), -np.inf)
    for mesh in meshes:
        grid, lo = _grid(mesh, axis, plane)
        cell = np.floor((flat - lo) / CELL_MM).astype(int)
        on = np.all((cell >= 0) & (cell < grid.shape), axis=1)
        out[on] = np.maximum(out[on], grid[cell[on, 0], cell[on, 1]])
    return out


def _grid(mesh: trimesh.Trimesh, axis: np.ndarray, plane: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(each square's ceiling over `mesh` (mm, -inf where no triangle reaches it), the grid's corner
    (2,) mm across the axis), made or kept (the mesh's hash changes with its vertices and faces)."""
    return _GRIDS.get((hash(mesh), axis.tobytes(), plane.tobytes()), lambda: _made(mesh, axis, plane))


def _made(mesh: trimesh.Trimesh, axis: np.ndarray, plane: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`_grid`'s grid of `mesh`, made: each square lifted to the highest corner of the triangles
    whose projected bounding boxes reach it."""
    projected = np.asarray(mesh.vertices) @ np.vstack([plane, axis]).T  # (V, 3): across, across, up
    lo = projected[:, :2].min(axis=0) - CELL_MM
    grid = np.full(tuple(np.floor((projected[:, :2].max(axis=0) - lo) / CELL_MM).astype(int) + 2), -np.inf)
    corners = [projected[mesh.faces[:, i]] for i in range(3)]
    least, most = np.minimum(np.minimum(*corners[:2]), corners[2]), np.maximum(np.maximum(*corners[:2]), corners[2])
    low = np.floor((least[:, :2] - PAD_MM - lo) / CELL_MM).astype(int)  # (T, 2) first square
    span = np.floor((most[:, :2] + PAD_MM - lo) / CELL_MM).astype(int) - low + 1  # (T, 2) squares
    count = span[:, 0] * span[:, 1]
    tri = np.repeat(np.arange(len(count)), count)
    k = np.arange(len(tri)) - np.repeat(np.cumsum(count) - count, count)
    np.maximum.at(grid, (low[tri, 0] + k // span[tri, 1], low[tri, 1] + k % span[tri, 1]), most[tri, 2] + PAD_MM)
    grid.flags.writeable = False
    return grid, lo
