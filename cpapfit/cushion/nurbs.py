"""The cushion as a NURBS surface (geomdl): AROUND x ROWS = 32 x 8 = 256 control points.

u runs around the seal (periodic), v from the face to the frame (clamped). Row 0 is solved so
that the surface's face-side boundary passes through the seal curve on the patient (the
paper's step: control points moved onto the warped contact region); rows 1-2 carry the seal
flange outwards along the skin; rows 3-7 form the wall rising to the frame interface: a
planar elliptic ring, the same for every patient, at a fixed clearance above the nose tip.

The self-sealing membrane is a second NURBS surface, AROUND x MEMBRANE_ROWS: a thin flap rooted
inside the flange at the seal curve and reaching inwards along the skin, its width set per column
(`cpapfit.cushion.envelope`); the CPAP pressure in the mask lays it on the skin where the wall lifts off.
"""

from dataclasses import dataclass

import numpy as np
import trimesh
from geomdl import NURBS, helpers
from scipy.ndimage import gaussian_filter1d

from .contact import Contact, closed_resample
from ..evaluation.membrane import LIFT, ROOT_MM
from ..frozen import freeze_arrays

AROUND, ROWS, DEGREE = 32, 8, 3
# The flange's rows in units of the flange width: (outwards across the seal, up off the skin).
# Row 0 is the seal curve; the flange turns up gently so that the wall never bends tighter than
# its own thickness.
FLANGE_PROFILE = ((0.0, 0.0), (0.45, 0.0), (0.9, 0.4), (1.15, 1.5))
WALL_STEPS = (0.12, 0.32, 0.62, 1.0)  # the wall's rows along its curve: close together where it leaves the flange
WALL_SMOOTHING = 1.0  # periodic Gaussian (in control columns) on the wall rows: no tight corners around the wall
FRAME_RING_MM = {"nasal": (48.0, 46.0), "oronasal": (86.0, 98.0)}  # (width, height) of the frame ring
MEMBRANE_ROWS = 4  # root, two inner rows, free edge: one cubic Bezier across the flap
MEMBRANE_ROOT_MM = (1.0, ROOT_MM)  # the flap's root inside the flange: outwards along the skin, up off it
MEMBRANE_LIFT = LIFT  # at rest the free edge stands this share of the flap's width off the skin plane (the reach's law takes both)
FLAP_SMOOTHING = 1.5  # periodic Gaussian (in control columns) on the flaps' directions: fanned, not square, at a tight bend


@dataclass(frozen=True)
class CushionParams:
    """Design parameters (mm): wall thickness, seal flange width along the skin, membrane thickness, interference
    (rim pre-load into the skin), frame clearance above the nose tip."""

    wall_mm: float = 2.0
    flange_mm: float = 5.0
    membrane_mm: float = 0.5
    interference_mm: float = 0.0
    frame_clearance_mm: float = 10.0


@dataclass(frozen=True)
class Cushion:
    """control: (AROUND, ROWS, 3) mm control points of the wall; membrane: (AROUND, MEMBRANE_ROWS, 3)
    mm control points of the membrane (None: none), membrane_thickness: (AROUND,) mm at each of its
    control columns (None: `params.membrane_mm` throughout); axis, up: unit mask axis (out of the
    face) and head-up direction; mask: "nasal" | "oronasal"."""

    mask: str
    control: np.ndarray
    axis: np.ndarray
    up: np.ndarray
    params: CushionParams
    membrane: np.ndarray | None = None
    membrane_thickness: np.ndarray | None = None

    def __post_init__(self):
        freeze_arrays(self)

    def surface(self) -> NURBS.Surface:
        """The wall's geomdl surface (`nurbs_surface`)."""
        return nurbs_surface(self.control)

    def grid(self, n_u: int = 128, n_v: int = 24) -> np.ndarray:
        """(n_u, n_v, 3) points of the wall: u around the seal (not repeating the start), v face to frame."""
        return surface_grid(self.control, n_u, n_v)

    def membrane_grid(self, n_u: int = 128, n_v: int = 8) -> np.ndarray:
        """(n_u, n_v, 3) points of the membrane: u around the seal, v from its root to its free edge."""
        return surface_grid(self.membrane, n_u, n_v)

    def membrane_thickness_at(self, n_u: int = 128) -> np.ndarray:
        """(n_u,) mm: the membrane's thickness at the n_u points around the seal of `membrane_grid`,
        linear between control columns (its k-th point lies on column k AROUND / n_u + 1, mod AROUND)."""
        if self.membrane_thickness is None:
            return np.full(n_u, self.params.membrane_mm)
        at = (np.arange(n_u) * AROUND / n_u + 1) % AROUND
        return np.interp(at, np.arange(AROUND + 1), np.append(self.membrane_thickness, self.membrane_thickness[0]))


def nurbs_surface(control: np.ndarray) -> NURBS.Surface:
    """The geomdl surface of an (AROUND, R, 3) control net: periodic in u (first DEGREE control
    columns repeated), clamped in v."""
    rows = control.shape[1]
    wrapped = np.concatenate([control, control[:DEGREE]], axis=0)
    surf = NURBS.Surface()
    surf.degree_u, surf.degree_v = DEGREE, DEGREE
    surf.ctrlpts_size_u, surf.ctrlpts_size_v = len(wrapped), rows
    surf.ctrlpts = wrapped.reshape(-1, 3).tolist()
    surf.weights = [1.0] * (len(wrapped) * rows)
    n_u = len(wrapped) + DEGREE + 1
    surf.knotvector_u = (np.arange(n_u) / (n_u - 1)).tolist()
    surf.knotvector_v = [0.0] * DEGREE + np.linspace(0, 1, rows - DEGREE + 1).tolist() + [1.0] * DEGREE
    return surf


def surface_grid(control: np.ndarray, n_u: int, n_v: int) -> np.ndarray:
    """(n_u, n_v, 3) points of the `nurbs_surface` of an (AROUND, R, 3) control net. The surface is
    a tensor product with unit weights, so the grid is geomdl's basis functions at the n_u and n_v
    parameters (a matrix each) applied to the control net."""
    surf = nurbs_surface(control)
    rows = control.shape[1]
    lo, hi = surf.knotvector_u[DEGREE], surf.knotvector_u[-DEGREE - 1]
    basis_u = _basis_matrix(surf.knotvector_u, surf.ctrlpts_size_u, lo + (hi - lo) * np.arange(n_u) / n_u)
    basis_v = _basis_matrix(surf.knotvector_v, rows, np.linspace(0.0, 1.0, n_v))
    net = np.asarray(surf.ctrlpts, dtype=np.float64).reshape(surf.ctrlpts_size_u, rows, 3)
    return np.einsum("ui,ijc,vj->uvc", basis_u, net, basis_v)


def _basis_matrix(knots: list, count: int, params: np.ndarray) -> np.ndarray:
    """(P, count) values of the degree-DEGREE B-spline basis functions at each parameter (geomdl)."""
    out = np.zeros((len(params), count))
    for row, t in enumerate(params):
        span = helpers.find_span_linear(DEGREE, knots, count, float(t))
        out[row, span - DEGREE: span + 1] = helpers.basis_function(DEGREE, knots, span, float(t))
    return out


def periodic_interpolation(points: np.ndarray) -> np.ndarray:
    """(N, 3) control points of the uniform periodic cubic B-spline through (N, 3) points at its knots."""
    n = len(points)
    basis = np.zeros((n, n))
    for i in range(n):  # at knot i the curve is (P[i-1] + 4 P[i] + P[i+1]) / 6
        basis[i, [(i - 1) % n, i, (i + 1) % n]] = [1 / 6, 4 / 6, 1 / 6]
    return np.linalg.solve(basis, points)


def design_cushion(
    contact: Contact, axis: np.ndarray, up: np.ndarray, apex: np.ndarray, params: CushionParams = CushionParams(),
    preload_mm: np.ndarray | None = None, membrane_mm: np.ndarray | None = None, skin: trimesh.Trimesh | None = None,
) -> Cushion:
    """The cushion on a seal: `axis` the mask axis (unit, out of the face), `up` the head's up
    direction, `apex` the point the cushion must clear (the nose tip), all in the scan frame (mm).
    `preload_mm` (K,): per seal-curve point, how far the rim is set into the skin along the axis
    (pressure compensation), on top of the uniform interference along the skin normal.
    `membrane_mm` (AROUND,): the membrane's width inwards from the seal curve at each control
    column (None: no membrane), laid along the `skin` (the registered face)."""
    rim = closed_resample(contact.curve, AROUND)
    normals = closed_resample(contact.curve, AROUND, contact.normals)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    rim = rim - params.interference_mm * normals
    centre = rim.mean(axis=0)
    out = _outward(rim, centre, normals, axis)
    ring = _frame_ring(rim, centre, axis, up, apex, contact.mask, params)
    f = params.flange_mm
    rows = [rim + f * (a * out + b * normals) for a, b in FLANGE_PROFILE]  # the seal flange, along the skin
    base = rows[-1]
    for t in WALL_STEPS:  # the wall, up to the frame ring
        lift = base + ((ring - base) @ np.outer(axis, axis))
        rows.append((1 - t) ** 2 * base + 2 * t * (1 - t) * lift + t**2 * ring)
    control = np.stack(rows, axis=1)  # (AROUND, ROWS, 3)
    wall = len(FLANGE_PROFILE) - 1
    control[:, wall:] = gaussian_filter1d(control[:, wall:], WALL_SMOOTHING, axis=0, mode="wrap")
    membrane = None if membrane_mm is None else _membrane_rows(rim, out, normals, np.asarray(membrane_mm, dtype=float), skin)
    if preload_mm is not None:  # the flange and its membrane move into the skin; the wall stretches, the frame ring stays
        sunk = closed_resample(contact.curve, AROUND, preload_mm)
        weight = np.concatenate([np.ones(len(FLANGE_PROFILE)), 1.0 - np.asarray(WALL_STEPS)])
        control -= np.einsum("i,j,c->ijc", sunk, weight, axis)
        membrane = None if membrane is None else membrane - np.einsum("i,c->ic", sunk, axis)[:, None]
    return Cushion(contact.mask, _interpolating(control), axis, up, params, None if membrane is None else _interpolating(membrane))


def _interpolating(rows: np.ndarray) -> np.ndarray:
    """The (AROUND, R, 3) control net whose surface passes through each row of (AROUND, R, 3) points at its knots."""
    return np.stack([periodic_interpolation(rows[:, j]) for j in range(rows.shape[1])], axis=1)


def _membrane_rows(rim: np.ndarray, out: np.ndarray, normals: np.ndarray, width: np.ndarray, skin: trimesh.Trimesh) -> np.ndarray:
    """(AROUND, MEMBRANE_ROWS, 3) mm: the membrane's rows from its root inside the flange
    (MEMBRANE_ROOT_MM) inwards to its free edge `width` (AROUND,) mm past the seal curve: square
    across the seal curve and along the `skin` (each row the point of the skin nearest a step on
    from the last, the step kept square to the curve, so that the flap climbs the side of the nose
    rather than running into it), standing off the skin by the root's height plus MEMBRANE_LIFT of
    the distance come."""
    root_out, root_up = MEMBRANE_ROOT_MM
    rows = [rim + root_out * out + root_up * normals]
    towards = flap_directions(rim, normals)
    tangent = trimesh.util.unitize(np.cross(towards, normals))
    on, step = rim, width[:, None] / (MEMBRANE_ROWS - 1)
    for row in range(1, MEMBRANE_ROWS):
        ahead, _, tri = trimesh.proximity.closest_point(skin, on + step * trimesh.util.unitize(towards))
        up = skin.face_normals[tri] * np.sign(np.einsum("ij,ij->i", skin.face_normals[tri], normals))[:, None]
        towards = ahead - on
        towards -= np.einsum("ij,ij->i", towards, tangent)[:, None] * tangent
        on = ahead
        rows.append(on + (root_up + MEMBRANE_LIFT * row * step) * up)
    return np.stack(rows, axis=1)


def flap_directions(rim: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(AROUND, 3) unit directions the membrane's flaps leave the (AROUND, 3) seal points in, along
    the skin (unit `normals` (AROUND, 3)): `inwards`, smoothed around the seal by FLAP_SMOOTHING
    columns, so that where the seal curve bends tightly inwards the flaps fan out across the bend
    rather than all pointing at its centre."""
    towards = gaussian_filter1d(inwards(rim, normals), FLAP_SMOOTHING, axis=0, mode="wrap")
    return trimesh.util.unitize(towards - np.einsum("ij,ij->i", towards, normals)[:, None] * normals)


def inwards(loop: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(K, 3) unit directions square to a closed (K, 3) `loop` on the skin, along the skin (unit
    `normals` (K, 3)), towards its inside: one side of the loop everywhere, the side its centre is on
    overall (not point by point: where the skin faces sideways the centre lies along the normal)."""
    tangent = trimesh.util.unitize(np.roll(loop, -1, axis=0) - np.roll(loop, 1, axis=0))
    side = trimesh.util.unitize(np.cross(normals, tangent))
    return side * np.sign(np.einsum("ij,ij->", side, loop.mean(axis=0) - loop))


def _outward(rim: np.ndarray, centre: np.ndarray, normals: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(N, 3) unit directions pointing away from the seal's centre, along the skin where it can.
    Radial in the skin's tangent plane where the skin faces along the mask axis: the seal is
    star-shaped about its centre, so flanges laid out radially never cross where the curve bends
    inwards (beside the nostrils). Where the skin faces away from the centre instead (the side of
    a deep nose, up to facing a little backwards) the radial direction has no part along the skin;
    there the flange goes out across the axis in proportion, never back under the wall."""
    radial = rim - centre
    length = np.linalg.norm(radial, axis=1, keepdims=True)
    along = (radial - np.einsum("ij,ij->i", radial, normals)[:, None] * normals) / length
    share = np.linalg.norm(along, axis=1, keepdims=True)  # 1: radial lies along the skin
    across = radial - np.outer(radial @ axis, axis)
    across /= np.linalg.norm(across, axis=1, keepdims=True)
    out = along + (1.0 - share) * across
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _frame_ring(rim, centre, axis, up, apex, mask: str, params: CushionParams) -> np.ndarray:
    """(N, 3) points of the frame's elliptic ring matched to the rim points by angle about the axis."""
    up = up - (up @ axis) * axis
    up /= np.linalg.norm(up)
    side = np.cross(up, axis)
    height = max(float((rim @ axis).max()), float(apex @ axis)) + params.frame_clearance_mm
    origin = centre + (height - centre @ axis) * axis
    rel = rim - centre
    angle = np.arctan2(rel @ up, rel @ side)
    width, tall = FRAME_RING_MM[mask]
    return origin + np.outer(0.5 * width * np.cos(angle), side) + np.outer(0.5 * tall * np.sin(angle), up)
