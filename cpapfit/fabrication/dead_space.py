"""The mask's dead space: the air between the face and the connector's bore, which the patient
breathes back before fresh air (ml), held within DEAD_SPACE_LIMIT_ML by lowering the frame ring towards the
face where the face is large (`ring_clearance`).

The air is the inside of the cushion's sheet (its face-side opening carried back into the head
along the mask axis) with the frame's `airspace`, less the frame's solid (the spigot inside the
cushion's end) and whatever lies behind the skin: the air's intersection with the space in front
of the skin, whose underside is the skin's first crossing on columns along the mask axis COLUMN_MM
apart (a height field; casting the columns through the air itself instead, its close faces made
the count jump by 10 ml between designs 0.01 mm apart). The skin is the registered template (on
the scan within its residual, and whole where the scan has holes); the membrane and the flange's
contact band are taken as thin.
"""

import numpy as np
import trimesh

from ..cushion.nurbs import FRAME_RING_MM, Cushion
from ..solids import to_manifold, to_trimesh
from .frame import Frame
from .mould import capped
from ..thresholds import DEAD_SPACE_LIMIT_ML

COLUMN_MM = 1.0
BEHIND_MM = 40.0  # the seal's opening carried this far back into the head: behind any skin inside it
CUSHION_SHARE = 5.0 / 6.0  # of the limit, the most the cushion's inside may take before the ring comes down: the frame's air is the rest
LEAST_CLEARANCE_MM = 5.0  # the ring at least this far over the nose tip: the tip below the frame's lowest face (its groove, 4 mm)


def dead_space_ml(cushion: Cushion, frame: Frame, skin: trimesh.Trimesh) -> float:
    """The air (ml) enclosed by the cushion, the frame and the `skin` (mm, scan frame)."""
    air = to_manifold(_inside(cushion)) + to_manifold(frame.airspace) - to_manifold(frame.mesh)
    return volume_in_front(to_trimesh(air), skin, cushion.axis) / 1000.0


def ring_clearance(cushion: Cushion, skin: trimesh.Trimesh) -> float:
    """The frame ring's clearance over the nose tip (mm) for a face (`skin`, mm, scan frame) on which
    `cushion` is designed with its own (`params.frame_clearance_mm`): that, lowered where the air inside
    the cushion takes more than CUSHION_SHARE of the dead-space limit, by the excess over the ring's
    area (each mm the ring comes down takes about the ring's area of air), to LEAST_CLEARANCE_MM at least."""
    a, b = np.array(FRAME_RING_MM[cushion.mask]) / 2
    excess_mm3 = volume_in_front(_inside(cushion), skin, cushion.axis) - 1000.0 * CUSHION_SHARE * DEAD_SPACE_LIMIT_ML[cushion.mask]
    most = cushion.params.frame_clearance_mm
    return float(np.clip(most - excess_mm3 / (np.pi * a * b), min(LEAST_CLEARANCE_MM, most), most))


def _inside(cushion: Cushion, n_u: int = 128, n_v: int = 24) -> trimesh.Trimesh:
    """The solid inside the cushion's sheet (sampled n_u x n_v), its face opening carried BEHIND_MM back into the head."""
    grid = cushion.grid(n_u, n_v)
    return capped(np.concatenate([grid[:, :1] - BEHIND_MM * cushion.axis, grid], axis=1))


def volume_in_front(solid: trimesh.Trimesh, skin: trimesh.Trimesh, axis: np.ndarray, spacing: float = COLUMN_MM) -> float:
    """The volume (mm3) of a closed `solid` in front of the `skin` along the unit `axis` (out of the face):
    the solid's intersection (manifold3d) with the space in front of the skin (`_in_front`, on columns
    `spacing` mm apart)."""
    return float((to_manifold(solid) ^ to_manifold(_in_front(solid.vertices, skin, axis, spacing))).volume())


def _in_front(points: np.ndarray, skin: trimesh.Trimesh, axis: np.ndarray, spacing: float) -> trimesh.Trimesh:
    """The closed solid over (N, 3) `points` across the unit `axis` whose underside is the skin: columns
    along -axis on a square grid `spacing` mm apart, each from above the points down to the skin's first
    crossing (or below the points where it misses the skin), joined as a height field."""
    across = np.linalg.svd(np.eye(3) - np.outer(axis, axis))[0][:, :2]
    flat, along = points @ across, points @ axis
    u, v = (np.arange(flat[:, k].min() - spacing, flat[:, k].max() + 2.0 * spacing, spacing) for k in (0, 1))
    uu, vv = (g.ravel() for g in np.meshgrid(u, v, indexing="ij"))
    base = np.outer(uu, across[:, 0]) + np.outer(vv, across[:, 1])
    above = along.max() + 1.0
    floor = np.full(len(base), along.min() - 1.0)
    loc, ray, _ = skin.ray.intersects_location(base + above * axis, np.tile(-axis, (len(base), 1)), multiple_hits=False)
    floor[ray] = loc @ axis
    top = max(above, floor.max() + 1.0)
    vertices = np.vstack([base + floor[:, None] * axis, base + top * axis])
    return _closed(vertices, len(u), len(v))


def _closed(vertices: np.ndarray, nu: int, nv: int) -> trimesh.Trimesh:
    """The closed height-field solid of (2 nu nv, 3) `vertices`: an nu x nv grid's underside, then its top."""
    at = np.arange(nu * nv).reshape(nu, nv)
    a, b, c, d = at[:-1, :-1].ravel(), at[1:, :-1].ravel(), at[1:, 1:].ravel(), at[:-1, 1:].ravel()
    under = np.concatenate([np.stack([a, c, b], axis=1), np.stack([a, d, c], axis=1)])
    ring = np.concatenate([at[:, 0], at[-1, 1:], at[-2::-1, -1], at[0, -2:0:-1]])  # the grid's edge, once round
    p, q = ring, np.roll(ring, -1)
    top = nu * nv
    sides = np.concatenate([np.stack([p, q, q + top], axis=1), np.stack([p, q + top, p + top], axis=1)])
    mesh = trimesh.Trimesh(vertices, np.concatenate([under, under[:, ::-1] + top, sides]), process=False)
    return mesh if mesh.volume > 0 else trimesh.Trimesh(vertices, mesh.faces[:, ::-1], process=False)
