"""The cushion surface thickened into a printable solid: a closed, watertight, manifold tube."""

import numpy as np
import trimesh
from scipy.ndimage import gaussian_filter
from scipy.spatial import cKDTree

from .contact import closed_resample
from ..solids import PRINT_RESOLUTION_MM, self_intersecting_edges, to_manifold, to_trimesh
from .nurbs import Cushion

NORMAL_SMOOTHING = (3.0, 6.0)  # Gaussian widths over the sheet's normals before offsetting, in grid steps, tried in turn
OFFSET_PASSES = 5  # solids offset at most, each growing the offsets where the wall is thinner than set
MAX_OFFSET = 4.0  # no offset grows past this many times its set thickness
REACHED = 1.0 - 1e-9  # a wall this share of its set thickness has reached it (an offset measures its length to ~1e-13)


def thicken(grid: np.ndarray, thickness_mm: np.ndarray, face_normals_hint: np.ndarray,
            smoothing: float = NORMAL_SMOOTHING[0]) -> trimesh.Trimesh:
    """A closed solid from an (n_u, n_v, 3) sheet, periodic in u, offset by `thickness_mm` ((n_u,)
    along u, or (n_u, n_v) at each grid point) to the side away from the face (`face_normals_hint`:
    (n_u, 3) skin normals along the v=0 edge)."""
    n_u, n_v, _ = grid.shape
    sheet = trimesh.Trimesh(grid.reshape(-1, 3), sheet_faces(n_u, n_v), process=False)
    normals = np.array(sheet.vertex_normals).reshape(n_u, n_v, 3)
    normals = gaussian_filter(normals, (smoothing, smoothing, 0), mode=("wrap", "nearest", "nearest"))
    normals /= np.linalg.norm(normals, axis=2, keepdims=True)  # smoothed: the offset does not fold in tight bends
    if np.einsum("ij,ij->i", normals[:, 0], face_normals_hint).mean() < 0:
        normals = -normals
    outer = grid + np.broadcast_to(np.reshape(thickness_mm, (n_u, -1)), (n_u, n_v))[:, :, None] * normals
    vertices = np.concatenate([grid.reshape(-1, 3), outer.reshape(-1, 3)])
    n = n_u * n_v
    sheet, rim, ring = sheet_faces(n_u, n_v), _cap(n_u, n_v, 0, n), _cap(n_u, n_v, n_v - 1, n)
    for flip_sheet, flip_rim in ((False, False), (False, True), (True, False), (True, True)):
        faces = np.concatenate([  # the two sheets wound oppositely, and the two caps
            _oriented(sheet, flip_sheet), _oriented(sheet + n, not flip_sheet),
            _oriented(rim, flip_rim), _oriented(ring, not flip_rim),
        ])
        solid = trimesh.Trimesh(vertices, faces, process=False)
        if solid.is_winding_consistent:
            break
    if solid.volume < 0:
        solid.invert()
    return solid


def _oriented(faces: np.ndarray, flip: bool) -> np.ndarray:
    return faces[:, ::-1] if flip else faces


def sheet_faces(n_u: int, n_v: int) -> np.ndarray:
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


def cushion_sheet(cushion: Cushion, n_u: int = 128, n_v: int = 24) -> trimesh.Trimesh:
    """The cushion's face-side surface (no thickness) as a mesh: enough to find where it meets the face."""
    return trimesh.Trimesh(cushion.grid(n_u, n_v).reshape(-1, 3), sheet_faces(n_u, n_v), process=False)


def membrane_sheet(cushion: Cushion, n_u: int = 128, n_v: int = 8) -> trimesh.Trimesh:
    """The membrane's face-side surface (no thickness) as a mesh; the cushion must have a membrane."""
    return trimesh.Trimesh(cushion.membrane_grid(n_u, n_v).reshape(-1, 3), sheet_faces(n_u, n_v), process=False)


def cushion_solid(cushion: Cushion, skin_normals: np.ndarray, n_u: int = 128, n_v: int = 24) -> tuple[trimesh.Trimesh, float, int]:
    """(the printable wall, its thinnest wall in mm, its self-intersecting edges: 0 unless every
    smoothing folds): the NURBS surface sampled and `thickened` away from the face to the set wall."""
    solid, walls, folds = thickened(cushion.grid(n_u, n_v), np.full(n_u, cushion.params.wall_mm), closed_resample(skin_normals, n_u))
    return solid, float(walls.min()), folds


def thickened(grid: np.ndarray, target: np.ndarray, hint: np.ndarray) -> tuple[trimesh.Trimesh, np.ndarray, int]:
    """(solid, (n_u * n_v,) wall mm at each grid point, self-intersecting edges) of an (n_u, n_v, 3)
    sheet thickened to `target` (n_u,) mm along u away from the face (`hint`: (n_u, 3) skin normals
    along its v=0 edge). An offset along the smoothed normals thins the wall where the sheet bends,
    so each grid point's offset grows, by 1.02 over its wall's share of its target, until its wall
    reaches the target (OFFSET_PASSES solids at most; no offset over MAX_OFFSET times its target):
    the solid is as thick as set everywhere, not thicker where its neighbours bend; where the
    offset folds into itself, the offset directions are smoothed more (NORMAL_SMOOTHING). A share
    of REACHED counts as reached: an offset along a unit normal measures its set length only to
    within rounding, either side, and is not grown for the side it rounds to."""
    n_u, n_v, _ = grid.shape
    wanted = np.repeat(target, n_v).reshape(n_u, n_v)
    for smoothing in NORMAL_SMOOTHING:
        offset = wanted
        for _ in range(OFFSET_PASSES):
            solid = thicken(grid, offset, hint, smoothing)
            walls = wall_thickness(grid, solid.vertices[n_u * n_v:])
            share = walls.reshape(n_u, n_v) / wanted
            if share.min() >= REACHED:
                break
            offset = np.minimum(offset * np.where(share < REACHED, 1.02 / np.maximum(share, 0.25), 1.0), MAX_OFFSET * wanted)
        folds = self_intersecting_edges(solid)
        if folds == 0:
            break
    return solid, walls, folds


def wall_thickness(grid: np.ndarray, outer: np.ndarray) -> np.ndarray:
    """(n_u * n_v,) mm: the distance from each outer sheet point (offsets of the (n_u, n_v, 3) grid,
    in the same order) to the inner sheet. A point whose nearest grid vertex is its own base point
    lies over a smooth stretch, and its wall is its offset; the others (bends, folds) get the exact
    closest point on the inner sheet."""
    n_u, n_v, _ = grid.shape
    base = grid.reshape(-1, 3)
    idx = cKDTree(base).query(outer)[1]
    suspect = idx != np.arange(len(base))
    walls = np.linalg.norm(outer - base, axis=1)
    if suspect.any():
        inner = trimesh.Trimesh(base, sheet_faces(n_u, n_v), process=False)
        _, walls[suspect], _ = trimesh.proximity.closest_point(inner, outer[suspect])
    return walls


def with_membrane(cushion: Cushion, wall: trimesh.Trimesh, skin_normals: np.ndarray, n_u: int = 128,
                  n_v: int = 8) -> tuple[trimesh.Trimesh, tuple[float, float], int]:
    """(the printable cushion, (the membrane's thinnest wall mm, the least share of its set
    thickness it has anywhere, both measured on the thickened membrane before the union), how many
    of its edges cross it (`self_intersecting_edges`)): the
    cushion's `wall` solid united (manifold3d) with its membrane, the membrane's NURBS sheet
    `thickened` to its thickness along the seal (`Cushion.membrane_thickness_at`) away from the face
    (`skin_normals`: (K, 3) along the seal curve). Its root lies inside the flange, so the union
    joins them along the flange's inner edge. Where the union crosses itself, its features finer
    than PRINT_RESOLUTION_MM are collapsed (manifold3d's `simplify`, which moves the surface by up
    to about twice that): the slivers its boolean can leave where the flaps' roots meet the flange
    at a tight bend."""
    target = cushion.membrane_thickness_at(n_u)
    flap, walls, _ = thickened(cushion.membrane_grid(n_u, n_v), target, closed_resample(skin_normals, n_u))
    joined = to_manifold(wall) + to_manifold(flap)
    solid = to_trimesh(joined)
    crossings = self_intersecting_edges(solid)
    if crossings:
        solid = to_trimesh(joined.simplify(PRINT_RESOLUTION_MM))
        crossings = self_intersecting_edges(solid)
    return solid, (float(walls.min()), float((walls / np.repeat(target, n_v)).min())), crossings
