"""The mask's dead space: the air between the face and the connector's bore, which the patient
breathes back before fresh air (ml).

The air is the inside of the cushion's sheet (its face-side opening carried back into the head
along the mask axis) with the frame's `airspace`, less whatever lies behind the skin: measured in
columns along the mask axis (COLUMN_MM apart across it), each column's length inside the air and in
front of the skin's first crossing. The skin is the registered template (on the scan within its
residual, and whole where the scan has holes); the membrane and the flange's contact band are taken
as thin.
"""

import numpy as np
import trimesh

from .cushion.nurbs import Cushion
from .export import to_manifold, to_trimesh
from .frame import Frame
from .mould import plug

COLUMN_MM = 1.0
BEHIND_MM = 40.0  # the seal's opening carried this far back into the head: behind any skin inside it


def dead_space_ml(cushion: Cushion, frame: Frame, skin: trimesh.Trimesh, n_u: int = 128, n_v: int = 24) -> float:
    """The air (ml) enclosed by the cushion (sampled n_u x n_v), the frame and the `skin` (mm, scan frame)."""
    grid = cushion.grid(n_u, n_v)
    carried = np.concatenate([grid[:, :1] - BEHIND_MM * cushion.axis, grid], axis=1)
    air = to_trimesh(to_manifold(plug(carried)) + to_manifold(frame.airspace))
    return volume_in_front(air, skin, cushion.axis) / 1000.0


def volume_in_front(solid: trimesh.Trimesh, skin: trimesh.Trimesh, axis: np.ndarray, spacing: float = COLUMN_MM) -> float:
    """The volume (mm3) of a closed `solid` in front of the `skin` along the unit `axis` (out of the face):
    columns along -axis on a square grid `spacing` mm apart (offset from the grid's lines by an irrational
    share, so that no column runs along an edge), each the sum over its crossings of the solid of
    min(t, skin) signed by entering or leaving, t the distance along the column."""
    across = np.linalg.svd(np.eye(3) - np.outer(axis, axis))[0][:, :2]
    flat = solid.vertices @ across
    lo, hi = flat.min(axis=0), flat.max(axis=0)
    u, v = (np.arange(lo[k] + spacing * (0.5 + 0.1 * np.sqrt(2 + k)), hi[k], spacing) for k in (0, 1))
    uu, vv = (g.ravel() for g in np.meshgrid(u, v, indexing="ij"))
    start = np.outer(uu, across[:, 0]) + np.outer(vv, across[:, 1]) + ((solid.vertices @ axis).max() + 1.0) * axis
    down = np.tile(-axis, (len(start), 1))
    stop = np.full(len(start), np.inf)
    loc, ray, _ = skin.ray.intersects_location(start, down, multiple_hits=False)
    stop[ray] = (start[ray] - loc) @ axis
    loc, ray, tri = solid.ray.intersects_location(start, down, multiple_hits=True)
    t = np.minimum((start[ray] - loc) @ axis, stop[ray])
    sign = np.sign(solid.face_normals[tri] @ axis)  # +: entering from above (a face looking out of the face)
    return float(np.sum(-sign * t) * spacing**2)
