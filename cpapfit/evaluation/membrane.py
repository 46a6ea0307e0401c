"""The self-sealing membrane: a thin flap that the CPAP pressure inside the mask lays on the skin.

A stock cushion seals with a membrane, not with its wall: where the wall lifts off the skin (the
jaw drops, a pillow pushes the mask), the pressure in the mask pushes the flap down onto the skin,
and the seal holds while the flap still lies on it. Here a flap of width w (mm, from its root at the
wall's contact line to its free edge) and thickness t, held at its root by the far stiffer wall,
closes a seal opening g (normal to the skin) up to its reach: the largest opening at which the CPAP
pressure P still lays it BAND_MM along the skin. A plate clamped at its root, raised h over a plane
and laid on it by P, touches down tangent with no moment a = (72 D h / P)^(1/4) from its root (D =
E t^3 / (12 (1 - nu^2)), E 1 MPa, nu 0.49); the finite elements of the flap (`fe_membrane.py`,
geometrically nonlinear, `calibration.sealed_opening`, `bench/fe_calibration.py --membrane`) lay
it down a thickness sooner (the touch-down's concentrated force spreads over about t), and once
the drop is a sizeable share of a (large deflection) short of the plate's, so with a =
w - BAND_MM + t, the plate's drop d = P a^4 / (72 D), and the designed flap's rest shape (its skin
side ROOT_MM off the skin at the root with the wall touching, rising by LIFT away from it), the
reach is
    d (1 - LARGE d / a) - LIFT a / 3 - ROOT_MM,
at least 0 and at most w - BAND_MM (an inextensible flap hanging to the skin): within 0.11 mm of
the finite elements for 0.5 mm flaps 3-10 mm wide at 4-20 cmH2O (LARGE = 0.22 fitted to them; a
10 mm flap at 20 cmH2O hangs to the skin, where they do not converge), within 0.15 mm for 0.3 mm
flaps 3-8 mm wide where they converge. A 5 mm flap at 10 cmH2O
closes nothing; a 10 mm one 4.1 mm. Where the wall is pushed off the face altogether (the CPAP load,
less what the roots pull below, beats the headgear, `mechanics.least_force_n`), nothing holds.

The flap also pulls its wall towards the skin: between its root and where it lies it spans the
air, and its root takes ROOT_SHARE of the air's push on that span (the rest bears on the skin where
it touches down; the finite elements of the designed flap with its wall at the skin, within 3 %,
`calibration.root_pull`). `root_pull_kpa_mm` is that pull per mm of rim, with the span at which the
law above lays the flap at no opening; `mechanics.press` takes it off the CPAP load.

The membrane is found on any closed cushion mesh by its thickness (`face_thickness_mm`): faces whose opposite
side lies within MEMBRANE_MAX_MM inwards and faces back at them (a sheet's two sides, not the cap
across a wall's end); a designed wall is at least 1.9 mm thick everywhere.
"""

import numpy as np
import trimesh
from scipy.ndimage import grey_opening
from scipy.spatial import cKDTree

from .fe import SILICONE_KPA, SILICONE_POISSON

BAND_MM = 2.0  # the flap must lie this far along the skin to seal (the flange's lubrication path is 5 mm)
MEMBRANE_MAX_MM = 1.0  # thinner than this: membrane, not wall
INSIDE_MM = 1e-3  # rays start this far inside a face, so they do not meet it
SLAB_MM = 0.6  # a section across the rim takes in the membrane vertices this near its plane (they are <= 1 mm apart)
TANGENT_STEP = 4  # the rim's direction at a point: towards the point this many further on from the one as far back
ROOT_MM = 0.15  # the designed flap's skin side stands this far off the skin at its root (`cushion.nurbs`)
LIFT = 0.1  # and rises away from the skin by this slope at rest
LARGE = 0.22  # large deflection: the drop falls short by this share of drop / a (fitted to the finite elements)
RUN = 17  # a width holds only where it holds over this many rim points running (a grey opening)
FACING = -0.8  # a sheet's other side: its normal and the face's meet at cos below this
ROOT_SHARE = 0.70  # of the air's push on a flap's span, what its root takes (finite elements at no opening: 0.69-0.72, within 3 %)


def face_thickness_mm(mesh: trimesh.Trimesh) -> np.ndarray:
    """(F,) mm: the thickness at each face of a mesh: the distance from its centre, inwards along its
    normal, to the mesh where the face met there faces back (cos below FACING); inf where the ray
    meets nothing, as on a sheet's open side, or meets a face across its path (the cap over a wall's end)."""
    inward = -mesh.face_normals
    origins = mesh.triangles_center + INSIDE_MM * inward
    loc, ray, tri = mesh.ray.intersects_location(origins, inward, multiple_hits=False)
    opposite = np.einsum("ij,ij->i", mesh.face_normals[tri], mesh.face_normals[ray]) < FACING
    face = np.full(len(mesh.faces), np.inf)
    face[ray[opposite]] = np.linalg.norm(loc[opposite] - origins[ray[opposite]], axis=1) + INSIDE_MM
    return face


def vertex_thickness_mm(mesh: trimesh.Trimesh, face_mm: np.ndarray) -> np.ndarray:
    """(V,) mm: at each vertex of a mesh (and its copies at the same place), the least of the (F,)
    thicknesses `face_mm` of its faces."""
    corner = _copies(mesh.vertices)
    out = np.full(corner.max() + 1, np.inf)
    np.minimum.at(out, corner[mesh.faces.ravel()], np.repeat(face_mm, 3))
    return out[corner]


def _copies(vertices: np.ndarray) -> np.ndarray:
    """(V,) a label per place of (V, 3) vertices: copies of a vertex (the same three numbers) share one.
    Each row is compared as its 24 bytes (0.0 for -0.0), a third of the time of `np.unique(axis=0)`."""
    rows = np.ascontiguousarray(vertices, dtype=np.float64) + 0.0
    return np.unique(rows.view(np.dtype((np.void, rows.itemsize * 3))).ravel(), return_inverse=True)[1].ravel()


def bending_stiffness(thickness: np.ndarray, youngs_kpa: float = SILICONE_KPA, poisson: float = SILICONE_POISSON) -> np.ndarray:
    """Plate bending stiffness D (kPa mm^3) of silicone sheets `thickness` mm thick."""
    return youngs_kpa * np.asarray(thickness) ** 3 / (12.0 * (1.0 - poisson**2))


def reach_mm(width_mm: np.ndarray, thickness: np.ndarray, cpap_kpa: float) -> np.ndarray:
    """(K,) mm of seal opening the membrane closes at each rim point: the largest opening at which
    the CPAP pressure `cpap_kpa` still lays a flap of (K,) `width_mm` and `thickness` mm BAND_MM on
    the skin (module docstring; 0 where there is no membrane: width 0)."""
    width = np.asarray(width_mm, dtype=float)
    thick = np.where(width > 0, thickness, 1.0)
    laid = _laid_mm(_free_mm(width, thick), thick, cpap_kpa)
    return np.where(width > 0, np.clip(laid, 0.0, np.maximum(width - BAND_MM, 0.0)), 0.0)


def _free_mm(width: np.ndarray, thickness: np.ndarray) -> np.ndarray:
    """(K,) mm: the longest span a of a flap that still lies BAND_MM on the skin."""
    return np.maximum(width - BAND_MM + thickness, 0.0)


def _laid_mm(span: np.ndarray, thickness: np.ndarray, cpap_kpa: float) -> np.ndarray:
    """(K,) mm: the opening at which `cpap_kpa` lays flaps (K,) `thickness` mm thick on the skin
    `span` (K,) mm from their roots (module docstring; negative: short of the wall's touch)."""
    drop = cpap_kpa * span**4 / (72.0 * bending_stiffness(thickness))
    bent = np.minimum(drop / np.maximum(span, 1e-9), 0.5 / LARGE)  # drop / a, held where the law would turn back
    return drop * (1.0 - LARGE * bent) - LIFT * span / 3.0 - ROOT_MM


def root_pull_kpa_mm(width_mm: np.ndarray, thickness: np.ndarray, cpap_kpa: float, iterations: int = 48) -> np.ndarray:
    """(K,) kPa mm per mm of rim: how hard each flap's root pulls the wall towards the skin where
    the wall stands at it: ROOT_SHARE of the air's push `cpap_kpa` on the span the flap bridges from
    its root (ROOT_MM up, rising by LIFT) to where it lies, the span a at which the reach's law lays
    it at no opening (bisection). 0 where there is no flap or it does not lie BAND_MM on the skin
    (no seal: the air is on both sides of it)."""
    width = np.asarray(width_mm, dtype=float)
    thick = np.where(width > 0, thickness, 1.0)
    if cpap_kpa <= 0:
        return np.zeros(width.shape)
    free = _free_mm(width, thick)
    lies = (width > 0) & (_laid_mm(free, thick, cpap_kpa) >= 0.0)
    lo = np.minimum((LIFT * 72.0 * bending_stiffness(thick) / (12.0 * cpap_kpa)) ** (1.0 / 3.0), free)  # the law's least
    hi = free.copy()
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        short = _laid_mm(mid, thick, cpap_kpa) < 0.0
        lo, hi = np.where(short, mid, lo), np.where(short, hi, mid)
    return np.where(lies, ROOT_SHARE * cpap_kpa * hi, 0.0)


def width_for(reach: np.ndarray, thickness_mm: float, cpap_kpa: float, tol_mm: float = 1e-9) -> np.ndarray:
    """(K,) mm: the narrowest flap `thickness_mm` thick whose `reach_mm` at `cpap_kpa` is `reach` (K,)
    mm (bisection: the reach grows with the width), at least reach + BAND_MM."""
    need = np.asarray(reach, dtype=float)
    lo, hi = need + BAND_MM, need + BAND_MM
    while (short := reach_mm(hi, np.full(need.shape, thickness_mm), cpap_kpa) < need).any():
        hi = np.where(short, 2.0 * hi, hi)
    while (hi - lo).max() > tol_mm:
        mid = 0.5 * (lo + hi)
        short = reach_mm(mid, np.full(need.shape, thickness_mm), cpap_kpa) < need
        lo, hi = np.where(short, mid, lo), np.where(short, hi, mid)
    return hi


def rim_membrane(vertices: np.ndarray, thickness: np.ndarray, rim: np.ndarray, spread: int) -> tuple[np.ndarray, np.ndarray]:
    """(width (K,) mm, thickness (K,) mm) of the membrane at each point of a closed (K, 3) `rim`,
    measured on the cushion's section there: the membrane vertices (of (V, 3) `vertices` with (V,)
    `thickness` mm) within SLAB_MM of the plane across the rim at the point, among those hanging
    from the rim within `spread` points of it (nearest to them); the farthest of them from the
    point is the width, their mean thickness the thickness; then opened (the least over RUN points
    running, the most of those): a section that cuts a neighbouring flap lengthwise where the rim
    turns reads a few points too wide, never a whole stretch. Width 0 where the section has none."""
    thin = np.flatnonzero(thickness <= MEMBRANE_MAX_MM)
    points = vertices[thin]
    owner = cKDTree(rim).query(points)[1]
    tangent = np.roll(rim, -TANGENT_STEP, axis=0) - np.roll(rim, TANGENT_STEP, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    ring = np.arange(-spread, len(rim) + spread) % len(rim)  # the sections, wrapped past the rim's ends
    plane = np.column_stack([tangent, -np.einsum("ij,ij->i", rim, tangent)])[ring].T.copy()  # (4, K + 2 spread)
    window = owner[:, None] + np.arange(2 * spread + 1)  # (M, 2 spread + 1) the sections each may lie in, in `ring`
    along = sum(points[:, i:i + 1] * plane[i][window] for i in range(3)) + plane[3][window]
    pair, step = np.nonzero(np.abs(along) <= SLAB_MM)
    near, k = thin[pair], ring[window[pair, step]]
    offset = vertices[near] - rim[k]
    width = np.zeros(len(rim))
    np.maximum.at(width, k, np.linalg.norm(offset, axis=1))
    count = np.bincount(k, minlength=len(rim))
    mean_t = np.bincount(k, weights=thickness[near], minlength=len(rim)) / np.maximum(count, 1)
    return grey_opening(width, size=RUN, mode="wrap"), mean_t
