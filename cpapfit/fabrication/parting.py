"""Parting surfaces of the casting mould: where one mould part gives way to another, as height
fields a = h(b, c) over a grid across a pull direction a (mm), found by casting rays along a
through the cast, and the solid on a part's side of one.

`between` splits two parts pulled apart along ±a: each takes the cast's surface it sees (the
surface first met from its side), so that no face it moulds leans back against its pull. `under`
marks out a part pulled along -a beneath the cast: only where the surface first met from below
faces down steeply does it take the cast's underside; elsewhere the parts around it do.
"""

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy import ndimage

from ..frozen import freeze_arrays

GRID_MM = 1.0  # grid step of a parting surface
AWAY_MM = 1.5  # a part absent from a column: its surface this far below the region
TAKE_DEG = 15.0  # a part pulled from beneath the cast takes its underside only where that faces the pull this steeply (shallower: the halves do)
SMOOTHING = 2.0  # grid steps: the halves' parting surface smoothed (a Gaussian), within the middle half of the cast along each ray
OPENING = 2  # grid steps: a part taking the cast's underside takes no strip narrower than twice this, and no part of it is ringed by other parts


@dataclass(frozen=True)
class HeightField:
    """A parting surface: `basis` (3, 3) rows a (along which heights run), b, c (unit, scan frame);
    grid positions `b` (n_b,) and `c` (n_c,) mm; heights `h` (n_b, n_c) mm."""

    basis: np.ndarray
    b: np.ndarray
    c: np.ndarray
    h: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)

    def point(self, b: float, c: float) -> np.ndarray:
        """(3,) the surface's grid point nearest (b, c), in scan coordinates (mm)."""
        i, j = np.abs(self.b - b).argmin(), np.abs(self.c - c).argmin()
        return np.array([self.h[i, j], self.b[i], self.c[j]]) @ self.basis

    def solid(self, far: float) -> trimesh.Trimesh:
        """The closed solid between the surface and the plane a = `far` (above every height), scan frame."""
        n_b, n_c = self.h.shape
        grid = np.arange(n_b * n_c).reshape(n_b, n_c)
        cell = np.stack([grid[:-1, :-1].ravel(), grid[1:, :-1].ravel(), grid[1:, 1:].ravel(), grid[:-1, 1:].ravel()], axis=1)
        ring = np.concatenate([grid[:, 0], grid[-1, 1:], grid[-2::-1, -1], grid[0, -2:0:-1]])  # the grid's edge, once round
        B, C = np.meshgrid(self.b, self.c, indexing="ij")
        surface = np.stack([self.h.ravel(), B.ravel(), C.ravel()], axis=1)
        lid = surface[ring] * [0.0, 1.0, 1.0] + [far, 0.0, 0.0]
        centre = [far, self.b.mean(), self.c.mean()]
        top, nxt = n_b * n_c + np.arange(len(ring)), np.roll(np.arange(len(ring)), -1)
        faces = np.concatenate([
            cell[:, [0, 1, 2]], cell[:, [0, 2, 3]],
            np.stack([ring, top, ring[nxt]], axis=1), np.stack([ring[nxt], top, top[nxt]], axis=1),
            np.stack([top, np.full(len(ring), top[-1] + 1), top[nxt]], axis=1),
        ])
        mesh = trimesh.Trimesh(np.vstack([surface, lid, centre]) @ self.basis, faces, process=False)
        if mesh.volume < 0:  # wound consistently by construction: only the sign may be wrong
            mesh.invert()
        return mesh


def between(cast: trimesh.Trimesh, basis: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> HeightField:
    """The parting surface of two parts pulled along ±basis[0] around `cast` within the box [lo, hi]
    (mm, coordinates along `basis`' rows): midway between where a ray along basis[0] first enters the
    cast and where it last leaves it; beside the cast, the height of the nearest ray that met it."""
    b, c, ray, tri, t = _hits(cast, basis, lo, hi)
    first, last = _extremes(ray, t, (len(b), len(c)))
    met = np.isfinite(first)
    nearest = tuple(ndimage.distance_transform_edt(~met, return_distances=False, return_indices=True))
    first, last = first[nearest], last[nearest]
    smooth = ndimage.gaussian_filter((first + last) / 2, SMOOTHING)
    return HeightField(basis, b, c, np.clip(smooth, first + (last - first) / 4, last - (last - first) / 4))


def under(cast: trimesh.Trimesh, basis: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> HeightField:
    """The top of a part pulled along -basis[0] from beneath `cast` within the box [lo, hi] (mm, along
    `basis`' rows): midway through the cast's first layer along basis[0] where the surface met first
    faces -basis[0] with at least TAKE_DEG of draft, else AWAY_MM below the box (no part there); the
    area so taken opened by OPENING steps and its holes filled."""
    b, c, ray, tri, t = _hits(cast, basis, lo, hi)
    shape = (len(b), len(c))
    first, _ = _extremes(ray, t, shape)
    is_first = t == first.ravel()[ray]
    beyond = ~is_first
    second = np.full(first.size, np.inf)
    np.minimum.at(second, ray[beyond], t[beyond])
    facing = np.full(first.size, -1.0)
    facing[ray[is_first]] = -cast.face_normals[tri[is_first]] @ basis[0]
    second = second.reshape(shape)
    through = np.isfinite(second)
    drafted = through & (facing.reshape(shape) >= np.sin(np.radians(TAKE_DEG)))
    taken = through & ndimage.binary_fill_holes(ndimage.binary_opening(drafted, iterations=OPENING))
    return HeightField(basis, b, c, np.where(taken, (first + second) / 2, lo[0] - AWAY_MM))


def _hits(cast: trimesh.Trimesh, basis: np.ndarray, lo: np.ndarray, hi: np.ndarray):
    """Rays along basis[0] from below the box, one per grid point over [lo, hi] in basis[1], basis[2],
    from half a step outside `lo` (no grid line in the box's faces) to past `hi`: (b (n_b,), c (n_c,),
    each hit's ray (flat grid index), triangle, height)."""
    b = np.arange(lo[1] - GRID_MM / 2, hi[1] + 1.5 * GRID_MM, GRID_MM)
    c = np.arange(lo[2] - GRID_MM / 2, hi[2] + 1.5 * GRID_MM, GRID_MM)
    B, C = np.meshgrid(b, c, indexing="ij")
    start = lo[0] - 2 * AWAY_MM
    origins = np.stack([np.full(B.size, start), B.ravel(), C.ravel()], axis=1) @ basis
    where, ray, tri = cast.ray.intersects_location(origins, np.tile(basis[0], (len(origins), 1)), multiple_hits=True)
    return b, c, ray, tri, start + (where - origins[ray]) @ basis[0]


def _extremes(ray: np.ndarray, t: np.ndarray, shape: tuple) -> tuple[np.ndarray, np.ndarray]:
    """(shape) the least and greatest hit height of each ray (inf, -inf where none)."""
    first, last = np.full(shape[0] * shape[1], np.inf), np.full(shape[0] * shape[1], -np.inf)
    np.minimum.at(first, ray, t)
    np.maximum.at(last, ray, t)
    return first.reshape(shape), last.reshape(shape)
