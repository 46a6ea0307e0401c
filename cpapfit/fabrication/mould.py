"""A casting mould for a silicone cushion: three outer parts and a core (booleans with manifold3d).

The cushion's sheet carried on a little past its two openings (the core's prints, which seat it in
the outer mould) and capped there, united with the cushion, is the "plug". The core is the plug
minus the cushion (it fills the tube's opening). The outer mould is a block
around the plug minus the plug, in three parts (`parting.py`): a face plate pulled along the mask
axis towards the face, taking the cushion's underside where that faces it steeply, and two
halves pulled apart across the head, split by a parting surface through the cushion's silhouette
as seen from the side, so that each takes the surface it sees. A pour spout and vents run from
the block's top (the frame side) into the cavity, and two keys (bumps on one half, sockets with
clearance on the other) register the halves.

Demoulding (`draft.py`): the draft of each part's moulding surface (its faces that touch the
cushion) along its pull is measured; the core is drawn along the mask axis through whichever
opening leaves less undercut. What is left undercut is reported for the caster: demoulding there
relies on the cured silicone flexing.
"""

from dataclasses import dataclass

import manifold3d as m3
import numpy as np
import trimesh
from trimesh.ray.ray_util import contains_points

from ..cushion.nurbs import Cushion
from ..cushion.solid import sheet_faces
from .draft import Draft, draft
from ..solids import to_manifold, to_trimesh
from .files import clean_as_written
from .parting import AWAY_MM, GRID_MM, between, under

MARGIN_MM = 8.0  # mould wall around the cushion
SPOUT_MM, VENT_MM = 6.0, 2.0  # diameters
PRINT_MM = 4.0  # the core reaches this far past each of the cushion's openings: no face of it lies in the plane of the cushion's end
CHANNEL_DIP_MM = 0.5  # channels start this far inside the cavity: none of their faces lies in the plane of the cushion's end
KEY_MM, KEY_CLEARANCE_MM = 3.0, 0.2  # key sphere radius, socket clearance
PROBE_MM = 0.01  # a part's face touches the cast when the cast is this far off it
PROBE_RAYS = np.array([[0.4395, 0.6176, 0.6522], [-0.7071, 0.5, 0.5], [0.2673, -0.5345, 0.8018]])  # fixed: no random retries


@dataclass(frozen=True)
class Mould:
    """The mould parts as trimesh solids: {"mould_left", "mould_right", "mould_face", "mould_core"},
    and the draft of each one's moulding surface along its pull direction (same keys)."""

    parts: dict
    draft: dict


def plug(grid: np.ndarray, axis: np.ndarray) -> trimesh.Trimesh:
    """The solid inside the cushion's sheet (an (n_u, n_v, 3) grid, mm), carried on PRINT_MM past
    both openings along the mask `axis` (unit) and capped there by fans."""
    return capped(np.concatenate([grid[:, :1] - PRINT_MM * axis, grid, grid[:, -1:] + PRINT_MM * axis], axis=1))


def capped(grid: np.ndarray) -> trimesh.Trimesh:
    """The solid inside a tube-shaped sheet (an (n_u, n_v, 3) grid, mm), both openings capped by fans."""
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
    filled = to_manifold(plug(cushion.grid(n_u, n_v), axis)) + cushion_m  # the union: the cushion is wholly inside
    local = solid.vertices @ frame.T
    lo, hi = local.min(axis=0) - MARGIN_MM, local.max(axis=0) + MARGIN_MM
    outer = m3.Manifold.cube(hi - lo).translate(lo).transform(_to_scan(frame)) - filled
    ring = cushion.grid(n_u, n_v)[:, -1] @ frame.T
    for k, diameter in ((0, SPOUT_MM), (n_u // 4, VENT_MM), (n_u // 2, VENT_MM), (3 * n_u // 4, VENT_MM)):
        outer = outer - _channel(ring[k], hi[2], diameter, frame)
    parts = _outer_parts(outer, to_trimesh(filled), frame, lo, hi) | {"mould_core": filled - cushion_m}
    parts = {name: clean_as_written(part) for name, part in parts.items()}
    return Mould(parts, demoulding(parts, solid, side, axis))


def _outer_parts(outer: m3.Manifold, filled: trimesh.Trimesh, frame: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> dict:
    """The outer mould in its parts {"mould_left", "mould_right", "mould_face"} (`frame`: rows side,
    up, axis; `lo`, `hi`: the block's corners along them, mm), the halves keyed, each in one piece
    (`_joined_pieces`). The face plate's grid is offset a quarter step from the halves' so that no
    grid lines of the two parting surfaces coincide."""
    along = [2, 0, 1]  # the face plate's frame: axis, side, up
    above = to_manifold(under(filled, frame[along], lo[along] - GRID_MM / 4, hi[along]).solid(hi[2] + AWAY_MM))
    rest = outer ^ above
    parting = between(filled, frame, lo, hi)
    left_side = to_manifold(parting.solid(hi[0] + AWAY_MM))
    left, right = rest ^ left_side, rest - left_side
    near = MARGIN_MM / 2 + GRID_MM / 4  # a quarter step off the midpoint of two parting grid lines, where a last bit picks one
    for y in (lo[1] + near, hi[1] - MARGIN_MM / 2):  # in the mould wall's corners, clear of the plug
        at = parting.point(y, lo[2] + near)
        left = left + m3.Manifold.sphere(KEY_MM, 32).translate(at)
        right = right - m3.Manifold.sphere(KEY_MM + KEY_CLEARANCE_MM, 32).translate(at)
    return _joined_pieces({"mould_left": left, "mould_right": right, "mould_face": outer - above})


def _joined_pieces(parts: dict) -> dict:
    """The outer parts (manifold3d) with every piece cut off from a part's largest body (the parting
    surfaces can isolate one between the cast and the other parts) joined to the other part its
    faces touch most (kept where they touch none)."""
    meshes = {name: to_trimesh(part) for name, part in parts.items()}
    joined = {}
    for name, part in parts.items():
        bodies = sorted(part.decompose(), key=lambda body: body.volume())
        joined.setdefault(name, []).append(bodies[-1])
        for piece in bodies[:-1]:
            joined.setdefault(_touching_most(to_trimesh(piece), {k: v for k, v in meshes.items() if k != name}) or name, []).append(piece)
    return {name: m3.Manifold.batch_boolean(joined[name], m3.OpType.Add) for name in parts}


def _touching_most(piece: trimesh.Trimesh, others: dict) -> str | None:
    """The name of the mesh in `others` that most of `piece`'s faces touch (PROBE_MM off them), or None."""
    probe = piece.triangles_center + PROBE_MM * piece.face_normals
    touching = {name: contains_points(mesh.ray, probe, check_direction=PROBE_RAYS[0]).sum() for name, mesh in others.items()}
    best = max(touching, key=touching.get)
    return best if touching[best] else None


def _to_scan(frame: np.ndarray) -> np.ndarray:
    """(3, 4) the affine map of the mould's frame (rows of `frame`) to scan coordinates."""
    return np.hstack([frame.T, np.zeros((3, 1))])


def demoulding(parts: dict, cast: trimesh.Trimesh, side: np.ndarray, axis: np.ndarray) -> dict:
    """{part name: Draft}: the halves pulled apart across the head (`side`, towards the left half),
    the face plate along the mask `axis` towards the face, the core along the axis out through
    whichever opening leaves less undercut."""
    pulls = {"mould_left": ((side, "across the head, towards the patient's left"),),
             "mould_right": ((-side, "across the head, towards the patient's right"),),
             "mould_face": ((-axis, "along the mask axis, towards the face"),),
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


def _channel(start: np.ndarray, top: float, diameter: float, frame: np.ndarray) -> m3.Manifold:
    """A cylinder along the mask axis from CHANNEL_DIP_MM inside the cavity below `start` (a point of
    the cushion's frame end, mould frame) to past the block's top `top`, in scan coordinates."""
    bottom = start - [0.0, 0.0, CHANNEL_DIP_MM]
    cylinder = m3.Manifold.cylinder(top - bottom[2] + 1.0, diameter / 2, diameter / 2, 32)
    return cylinder.translate(bottom.tolist()).transform(_to_scan(frame))
