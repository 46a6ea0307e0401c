"""A two-part casting mould with a core for a silicone cushion (booleans with manifold3d).

The cushion's sheet with its two openings capped, united with the cushion, is the "plug". The
core is the plug minus the cushion (it fills the tube's opening); the outer mould is a block around the plug
minus the plug, split in two along the plane through the mask axis and the head's up direction
so that each half comes off sideways. A pour spout and vents run from the block's top (the
frame side) into the cavity, and two keys on the parting face (bumps on one half, sockets with
clearance on the other) register the halves.

Demoulding (`draft.py`): each half is pulled straight off the parting plane, the core out along the
mask axis through whichever opening leaves less undercut; the draft of each part's moulding surface
(its faces that touch the cushion) is measured, not corrected: undercuts are reported for the
caster, and demoulding relies on the cured silicone flexing out of them.
"""

from dataclasses import dataclass

import manifold3d as m3
import numpy as np
import trimesh
from trimesh.ray.ray_util import contains_points

from .cushion.nurbs import Cushion
from .cushion.solid import sheet_faces
from .draft import Draft, draft
from .export import to_manifold, to_trimesh

MARGIN_MM = 8.0  # mould wall around the cushion
SPOUT_MM, VENT_MM = 6.0, 2.0  # diameters
KEY_MM, KEY_CLEARANCE_MM = 3.0, 0.2  # key sphere radius, socket clearance
PROBE_MM = 0.01  # a part's face touches the cast when the cast is this far off it
PROBE_RAYS = np.array([[0.4395, 0.6176, 0.6522], [-0.7071, 0.5, 0.5], [0.2673, -0.5345, 0.8018]])  # fixed: no random retries


@dataclass(frozen=True)
class Mould:
    """The mould parts as trimesh solids: {"mould_left", "mould_right", "mould_core"}, and the draft
    of each one's moulding surface along its pull direction (same keys)."""

    parts: dict
    draft: dict


def plug(grid: np.ndarray) -> trimesh.Trimesh:
    """The solid inside the cushion's sheet (an (n_u, n_v, 3) grid), both openings capped by fans."""
    n_u, n_v, _ = grid.shape
    pts = grid.reshape(-1, 3)
    rim_c, ring_c = grid[:, 0].mean(axis=0), grid[:, -1].mean(axis=0)
    vertices = np.vstack([pts, rim_c, ring_c])
    i = np.arange(n_u)
    rim = np.stack([i * n_v, ((i + 1) % n_u) * n_v, np.full(n_u, len(pts))], axis=1)
    ring = np.stack([((i + 1) % n_u) * n_v + n_v - 1, i * n_v + n_v - 1, np.full(n_u, len(pts) + 1)], axis=1)
    mesh = trimesh.Trimesh(vertices, np.concatenate([sheet_faces(n_u, n_v), rim[:, ::-1], ring[:, ::-1]]), process=False)
    if mesh.volume < 0:  # the fans are wound against the sheet along the shared rows: only the sign may be wrong
        mesh.invert()
    return mesh


def mould(cushion: Cushion, solid: trimesh.Trimesh, n_u: int = 128, n_v: int = 24) -> Mould:
    """The mould parts for a cushion whose printable solid is `solid` (same sampling)."""
    axis, up = cushion.axis, cushion.up - (cushion.up @ cushion.axis) * cushion.axis
    up /= np.linalg.norm(up)
    side = np.cross(up, axis)
    frame = np.stack([side, up, axis])  # rows: the mould's x, y, z in scan coordinates
    cushion_m = to_manifold(solid)
    filled = to_manifold(plug(cushion.grid(n_u, n_v))) + cushion_m  # the union: the cushion is wholly inside
    core = filled - cushion_m
    local = solid.vertices @ frame.T
    lo, hi = local.min(axis=0) - MARGIN_MM, local.max(axis=0) + MARGIN_MM
    to_scan = np.eye(4)
    to_scan[:3, :3] = frame.T
    block = m3.Manifold.cube(hi - lo).translate(lo).transform(to_scan[:3])
    outer = block - filled
    top = hi[2]
    centre = (lo + hi) / 2
    ring_local = cushion.grid(n_u, n_v)[:, -1] @ frame.T
    channels = [_channel(ring_local[0], top, SPOUT_MM, to_scan)] + [
        _channel(ring_local[k], top, VENT_MM, to_scan) for k in (n_u // 4, n_u // 2, 3 * n_u // 4)
    ]
    for ch in channels:
        outer = outer - ch
    left, right = outer.split_by_plane(side.tolist(), float(side @ (frame.T @ centre)))
    for y in (lo[1] + MARGIN_MM / 2, hi[1] - MARGIN_MM / 2):  # in the mould wall's corners, clear of the plug
        at = frame.T @ np.array([centre[0], y, lo[2] + MARGIN_MM / 2])
        key = m3.Manifold.sphere(KEY_MM, 32).translate(at)
        left, right = left + key, right - m3.Manifold.sphere(KEY_MM + KEY_CLEARANCE_MM, 32).translate(at)
    parts = {"mould_left": to_trimesh(left), "mould_right": to_trimesh(right), "mould_core": to_trimesh(core)}
    return Mould(parts, demoulding(parts, solid, side, axis))


def demoulding(parts: dict, cast: trimesh.Trimesh, side: np.ndarray, axis: np.ndarray) -> dict:
    """{part name: Draft}: the halves pulled off the parting plane (normal `side`, towards the left
    half), the core along the mask `axis` out through whichever opening leaves less undercut."""
    pulls = {"mould_left": ((side, "off the parting plane, towards the patient's left"),),
             "mould_right": ((-side, "off the parting plane, towards the patient's right"),),
             "mould_core": ((axis, "along the mask axis, out through the frame opening"),
                            (-axis, "along the mask axis, out through the face opening"))}
    return {name: _least_undercut(part, moulding_faces(part, cast), pulls[name]) for name, part in parts.items()}


def moulding_faces(part: trimesh.Trimesh, cast: trimesh.Trimesh) -> np.ndarray:
    """(K, 3) the faces of a mould part that touch the cast: just off them, along their outward normal,
    is the cast. Inside is where rays both ways along one of PROBE_RAYS cross the cast an odd number
    of times (trimesh's `contains` would retry grazing rays in a random direction: not repeatable)."""
    probe = part.triangles_center + PROBE_MM * part.face_normals
    inside = np.zeros(len(probe), dtype=bool)
    for direction in PROBE_RAYS:
        inside |= contains_points(cast.ray, probe, check_direction=direction)
    return part.faces[inside]


def _least_undercut(part: trimesh.Trimesh, faces: np.ndarray, pulls: tuple) -> Draft:
    """The draft of a part's moulding faces along the candidate pull ((direction, name), ...) that leaves least undercut."""
    return min((draft(part.vertices, faces, pull, name) for pull, name in pulls), key=lambda d: d.undercut_fraction)


def _channel(start_local: np.ndarray, top: float, diameter: float, to_scan: np.ndarray) -> m3.Manifold:
    """A vertical cylinder (along the mask axis) from a point of the cavity to the block's top."""
    height = top - start_local[2] + 1.0
    cyl = m3.Manifold.cylinder(height, diameter / 2, diameter / 2, 32)
    return cyl.translate(start_local.tolist()).transform(to_scan[:3])
