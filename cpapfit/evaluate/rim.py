"""Where a cushion meets the face: its contact line, found from the cushion's own mesh.

The cushion (any triangle mesh in the scan frame: the designed solid, an STL from elsewhere, a
stock cushion) is refined to ~1 mm edges; every vertex looks down the mask axis for the skin.
Around the axis, in SECTORS equal angles, the vertex with the least clearance is the rim's
contact point in that direction: the first part of the cushion the skin meets when the mask is
pushed on. Evaluating the written mesh (not the design's internal curve) means `design` and
`evaluate` measure the same thing.
"""

from dataclasses import dataclass

import numpy as np
import trimesh

from ..errors import InputError
from ..frozen import freeze_arrays

SECTORS = 256
REFINE_MM = 1.0  # longest cushion edge after refinement
REACH_MM = 60.0  # rays start this far above each vertex, so rims pressed into the skin are found too
TIE_MM = 0.1  # clearances this close count as equal when choosing a sector's rim point
FACE_MM = 4.0  # scanned skin farther than this from the registered face along the ray: a hole in the scan


@dataclass(frozen=True)
class RimContact:
    """A cushion's contact line over the face, one point per sector around the mask axis.

    points: (K, 3) mm rim points on the cushion; skin: (K, 3) mm skin below each, along -axis;
    clearance: (K,) mm from rim to skin along the axis (negative: rim inside the skin; NaN where
    no skin was found, i.e. not covered); cos: (K,) |cos| of the angle between the face's normal
    (the registered template's, smooth where the scan is noisy) and the axis; ds: (K,) mm of rim length each point stands for; uv: (K, 2) mm in-plane position about
    the rim's centre (side, up); sealed_area_mm2: area inside the rim, across the axis."""

    points: np.ndarray
    skin: np.ndarray
    clearance: np.ndarray
    cos: np.ndarray
    ds: np.ndarray
    uv: np.ndarray
    axis: np.ndarray
    sealed_area_mm2: float

    def __post_init__(self):
        freeze_arrays(self)

    @property
    def covered(self) -> np.ndarray:
        """(K,) bool: skin found under the rim point."""
        return np.isfinite(self.clearance)


def in_plane(axis: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(2, 3) unit (side, up) directions across the unit mask `axis`."""
    up = up - (up @ axis) * axis
    up = up / np.linalg.norm(up)
    return np.stack([np.cross(up, axis), up])


def find_rim(
    cushion: trimesh.Trimesh, scan_mesh: trimesh.Trimesh, face_mesh: trimesh.Trimesh, axis: np.ndarray, up: np.ndarray,
    sectors: int = SECTORS,
) -> RimContact:
    """The contact line of a `cushion` mesh over a `scan_mesh`, both mm in the scan frame. The
    rim is found against `face_mesh` (the registered template: the whole face, no holes), its
    clearance is measured against the scan; where the scan's skin is missing or lies farther than
    FACE_MM from the face (a ray through a hole), the point is not covered. `axis`: the unit mask
    axis (out of the face); `up`: the head's up direction."""
    vertices, _ = trimesh.remesh.subdivide_to_size(cushion.vertices, cushion.faces, REFINE_MM)
    on_face, _, face_cos = _look_down(vertices, face_mesh, axis)
    plane = in_plane(axis, up)
    uv = (vertices - vertices.mean(axis=0)) @ plane.T
    sector = np.minimum((np.arctan2(uv[:, 1], uv[:, 0]) + np.pi) / (2 * np.pi) * sectors, sectors - 1).astype(int)
    level = np.round(np.nan_to_num(on_face, nan=np.inf) / TIE_MM)  # ties (a flange flat on the skin): the inner edge
    order = np.lexsort((np.linalg.norm(uv, axis=1), level, sector))
    first = order[np.unique(sector[order], return_index=True)[1]]  # least clearance in each sector
    if len(first) < sectors or not np.isfinite(on_face[first]).all():
        raise InputError("the cushion does not run all the way round the mask axis over the face")
    pts = vertices[first]
    clearance, skin, _ = _look_down(pts, scan_mesh, axis)
    clearance[np.abs(clearance - on_face[first]) > FACE_MM] = np.nan
    rim_uv = (pts - pts.mean(axis=0)) @ plane.T
    return RimContact(pts, skin, clearance, face_cos[first], _arc_lengths(pts), rim_uv, axis, _area(rim_uv))


def _look_down(vertices: np.ndarray, scan_mesh: trimesh.Trimesh, axis: np.ndarray):
    """(clearance (V,) mm, NaN where no skin; skin points (V, 3); |cos| skin normal to axis (V,))."""
    origins = vertices + REACH_MM * axis
    loc, ray, tri = scan_mesh.ray.intersects_location(origins, np.tile(-axis, (len(vertices), 1)), multiple_hits=False)
    clearance = np.full(len(vertices), np.nan)
    clearance[ray] = np.linalg.norm(loc - origins[ray], axis=1) - REACH_MM
    skin = np.full((len(vertices), 3), np.nan)
    skin[ray] = loc
    cos = np.ones(len(vertices))
    cos[ray] = np.abs(scan_mesh.face_normals[tri] @ axis)
    return clearance, skin, cos


def _arc_lengths(loop: np.ndarray) -> np.ndarray:
    """(K,) half the distance to each neighbour along a closed (K, 3) loop (sums to its length)."""
    step = np.linalg.norm(np.roll(loop, -1, axis=0) - loop, axis=1)
    return 0.5 * (step + np.roll(step, 1))


def _area(uv: np.ndarray) -> float:
    """Area (mm^2) of the closed polygon (K, 2) (shoelace)."""
    u, v = uv[:, 0], uv[:, 1]
    return float(0.5 * abs(u @ np.roll(v, -1) - v @ np.roll(u, -1)))
