"""The cushion surface thickened into a printable solid: a closed, watertight, manifold tube."""

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..contact import closed_resample
from .nurbs import Cushion


def thicken(grid: np.ndarray, thickness_mm: float, face_normals_hint: np.ndarray) -> trimesh.Trimesh:
    """A closed solid from an (n_u, n_v, 3) sheet, periodic in u, offset by `thickness_mm` to the
    side away from the face (`face_normals_hint`: (n_u, 3) skin normals along the v=0 edge)."""
    n_u, n_v, _ = grid.shape
    sheet = trimesh.Trimesh(grid.reshape(-1, 3), _sheet_faces(n_u, n_v), process=False)
    normals = np.array(sheet.vertex_normals).reshape(n_u, n_v, 3)
    if np.einsum("ij,ij->i", normals[:, 0], face_normals_hint).mean() < 0:
        normals = -normals
    outer = grid + thickness_mm * normals
    n = n_u * n_v
    faces = np.concatenate([
        _sheet_faces(n_u, n_v),  # inner sheet
        _sheet_faces(n_u, n_v) + n,  # outer sheet
        _cap(n_u, n_v, 0, n),  # the rim at the face
        _cap(n_u, n_v, n_v - 1, n),  # the ring at the frame
    ])  # winding made consistent and outward below
    solid = trimesh.Trimesh(np.concatenate([grid.reshape(-1, 3), outer.reshape(-1, 3)]), faces, process=False)
    trimesh.repair.fix_winding(solid)
    trimesh.repair.fix_inversion(solid)
    return solid


def _sheet_faces(n_u: int, n_v: int) -> np.ndarray:
    """Two triangles per grid cell, u wrapping around."""
    i, j = np.meshgrid(np.arange(n_u), np.arange(n_v - 1), indexing="ij")
    a = i * n_v + j
    b = ((i + 1) % n_u) * n_v + j
    return np.concatenate([np.stack([a, b, a + 1], -1).reshape(-1, 3), np.stack([b, b + 1, a + 1], -1).reshape(-1, 3)])


def _cap(n_u: int, n_v: int, j: int, offset: int) -> np.ndarray:
    """The strip joining the inner and outer sheets along row j."""
    i = np.arange(n_u)
    a, b = i * n_v + j, ((i + 1) % n_u) * n_v + j
    return np.concatenate([np.stack([a, a + offset, b], -1), np.stack([b, a + offset, b + offset], -1)])


def cushion_solid(cushion: Cushion, skin_normals: np.ndarray, n_u: int = 128, n_v: int = 24) -> tuple[trimesh.Trimesh, float]:
    """(the printable cushion, its thinnest wall in mm). The NURBS surface is sampled and thickened
    away from the face; where the wall bends, an offset thins it on the inside of the bend, so
    the offset grows (at most twice) until the thinnest wall reaches the set thickness."""
    grid = cushion.grid(n_u, n_v)
    hint = closed_resample(skin_normals, n_u)
    target = cushion.params.wall_mm
    offset = target
    for _ in range(3):
        solid = thicken(grid, offset, hint)
        wall = thinnest_wall(grid, solid.vertices[n_u * n_v:], offset)
        if wall >= target:
            break
        offset *= 1.02 * target / max(wall, 0.25 * target)
    return solid, wall


def thinnest_wall(grid: np.ndarray, outer: np.ndarray, wall_mm: float) -> float:
    """Least distance (mm) from the outer sheet's points to the inner sheet (an (n_u, n_v, 3) grid):
    exact closest points for the candidates a k-d tree on the grid finds within reach."""
    n_u, n_v, _ = grid.shape
    near, _ = cKDTree(grid.reshape(-1, 3)).query(outer)
    spacing = float(np.linalg.norm(np.diff(grid, axis=1), axis=-1).max())
    suspect = near < wall_mm + spacing
    if not suspect.any():
        return float(near.min())
    inner = trimesh.Trimesh(grid.reshape(-1, 3), _sheet_faces(n_u, n_v), process=False)
    _, dist, _ = trimesh.proximity.closest_point(inner, outer[suspect])
    return float(min(dist.min(), near[~suspect].min(initial=np.inf)))
