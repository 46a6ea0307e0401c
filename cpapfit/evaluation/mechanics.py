"""The mask as a rigid body on an elastic face: equilibrium under headgear and CPAP.

Rim point i, pushed along the mask axis by a_i = d + tilt . uv_i - clearance_i (mm; d the
mask's shift towards the face, tilt (2,) its slopes across the axis), indents the skin along
its normal by a_i * cos_i and presses back with p_i = k_i * a_i * cos_i (kPa) over the contact
area A_i = flange width * ds_i; along the axis that is a spring of stiffness k_i A_i cos_i^2.
The headgear force F (N) pushes along the axis through the centroid of the contact band
(weighted by A_i cos_i); the CPAP pressure P over the sealed area pushes the mask off, taken
through the same line. A membrane flap pulls its wall towards the skin by its root's share of the
air's push on the span it bridges to the skin (`membrane.root_pull_kpa_mm`): the pull q_i (N, along
the axis) where the wall stands at the skin or off it, easing to none once the wall is pressed
ROOT_MM into it (its root is down on the skin then, and the flap lies on the skin from there),
and none where the flap no longer closes the opening (`press`). The equilibrium minimises the
convex energy
    sum_i [1/2 k_i A_i cos_i^2 max(a_i, 0)^2 + V_i(a_i)] - (F - P * sealed area) * d,
V_i' = -q_i min(max(1 - a_i cos_i / ROOT_MM, 0), 1), i.e. force balance along the axis and moment
balance about the two axes across it; with no contact at all the pulls must hold the mask on
alone (`least_force_n`), else the CPAP load lifts it off. Where p_i < P the air lifts the seal
open by (P - p_i) / k_i (normal, mm).
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize
from scipy.spatial import ConvexHull

from ..frozen import freeze_arrays
from ..kept import Kept
from .membrane import ROOT_MM

COS_MIN = 0.2  # skin steeper than ~78 degrees to the axis is treated as 78 degrees
N_PER_KPA_MM2 = 1e-3
_HULLS = Kept(4)


@dataclass(frozen=True)
class Pressed:
    """The mask at equilibrium: shift_mm along the axis (from first touch), tilt (2,) slopes;
    pressure_kpa (K,) contact pressure on the skin; opening_mm (K,) seal opening (0: closed);
    lifted: the CPAP load, less what the membrane's pulls can hold, exceeds the headgear force, or
    tips the mask off about an edge of the rim (no contact can hold)."""

    shift_mm: float
    tilt: np.ndarray
    pressure_kpa: np.ndarray
    opening_mm: np.ndarray
    lifted: bool

    def __post_init__(self):
        freeze_arrays(self)


def cpap_load_n(cpap_kpa: float, sealed_area_mm2: float) -> float:
    """N: the CPAP pressure's push on the area a rim seals (mm^2)."""
    return cpap_kpa * sealed_area_mm2 * N_PER_KPA_MM2


def pull_n(pull_kpa_mm: np.ndarray, ds: np.ndarray, cos: np.ndarray) -> np.ndarray:
    """(K,) N along the axis: the flaps' pulls (K,) kPa mm per mm of rim (`membrane.root_pull_kpa_mm`)
    over rim lengths `ds` (K,) mm, at skin slopes `cos` (K,)."""
    return pull_kpa_mm * ds * np.maximum(cos, COS_MIN) * N_PER_KPA_MM2


def least_force_n(cos, area_mm2, uv, sealed_area_mm2: float, cpap_kpa: float, pull: np.ndarray) -> float:
    """N: the least headgear force that holds a rim on (arguments as `press`'s; `pull` (K,) N): the
    CPAP load less the most the flaps' pulls hold against it, off the skin, about any edge of the
    rim's convex hull the mask could tip over (sum_i q_i d_i / d_c, d the distances inside the edge
    of each point and of the load's line of action); pulls even around the rim hold their whole sum."""
    if not np.any(pull):
        return cpap_load_n(cpap_kpa, sealed_area_mm2)
    centre = _centre(cos, area_mm2, uv)
    hull = _HULLS.get(np.ascontiguousarray(uv, dtype=float).tobytes(), lambda: _hull(uv))  # (E, 3): unit normal out of the hull, offset
    inside = -(uv @ hull[:, :2].T + hull[:, 2])  # (K, E) mm inside each edge
    held = (pull @ inside) / -(hull[:, :2] @ centre + hull[:, 2])
    return cpap_load_n(cpap_kpa, sealed_area_mm2) - float(held.min())


def _hull(uv: np.ndarray) -> np.ndarray:
    """(E, 3) the edges of the convex hull of (K, 2) mm rim points: unit normal out of the hull, offset
    (read-only: kept in _HULLS, as a force search presses one rim at many forces)."""
    equations = ConvexHull(uv).equations
    equations.flags.writeable = False
    return equations


def _centre(cos, area_mm2, uv) -> np.ndarray:
    """(2,) mm: the load's line of action, the contact band's centroid (weighted by area |cos|)."""
    cos = np.maximum(cos, COS_MIN)
    return (area_mm2 * cos) @ uv / (area_mm2 @ cos)


@dataclass(frozen=True)
class Flaps:
    """The membrane at K rim points as the mechanics takes it: pull_n (K,) N along the axis
    (`pull_n`), reach_mm (K,) mm the seal opening each flap closes (`membrane.reach_mm`)."""

    pull_n: np.ndarray
    reach_mm: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)


def press(clearance, cos, area_mm2, k, uv, sealed_area_mm2: float, force_n: float, cpap_kpa: float,
          flaps: Flaps | None = None, near: Pressed | None = None) -> Pressed:
    """Equilibrium of a rim of K points (arrays (K,), uv (K, 2), all covered) under `force_n` N
    of headgear and `cpap_kpa` over `sealed_area_mm2`; k (K,) kPa/mm normal stiffness; `flaps` the
    membrane (None: none). A flap pulls only while it closes its point's opening: an equilibrium
    that opens a point past its flap's reach is found again without that pull (the flap no longer
    seals there, so the air is on both sides of it), until none does. `near`: the same rim's
    equilibrium at another force, where the search starts (the same minimum within the search's
    tolerance, in fewer steps)."""
    pull = np.zeros(len(clearance)) if flaps is None else flaps.pull_n
    while True:
        pressed = near = _equilibrium(clearance, cos, area_mm2, k, uv, sealed_area_mm2, force_n, cpap_kpa, pull, near)
        if pressed.lifted or flaps is None:
            return pressed
        sealing = np.where(pressed.opening_mm <= flaps.reach_mm, pull, 0.0)
        if np.array_equal(sealing, pull):
            return pressed
        pull = sealing


def _equilibrium(clearance, cos, area_mm2, k, uv, sealed_area_mm2, force_n, cpap_kpa, pull, near: Pressed | None = None) -> Pressed:
    """`press` with every pull (K,) N held (module docstring), the search started at `near` (else settled untilted)."""
    lifted = force_n <= least_force_n(cos, area_mm2, uv, sealed_area_mm2, cpap_kpa, pull)
    cos = np.maximum(cos, COS_MIN)
    spring = k * area_mm2 * cos**2 * N_PER_KPA_MM2  # N/mm along the axis
    net = force_n - cpap_load_n(cpap_kpa, sealed_area_mm2)
    basis = np.column_stack([np.ones(len(clearance)), uv - _centre(cos, area_mm2, uv)])
    touch = float(clearance.min())
    if lifted:
        along = touch - clearance
        return _pressed(along, cos, k, cpap_kpa, 0.0, np.zeros(2), lifted=True)
    ridge = 1e-9 * float(spring.sum()) * np.diag([0.0, *np.mean(uv**2, axis=0)])  # pins the tilt of a rim touching at one point
    ease = ROOT_MM / cos  # mm along the axis: pressed this far in, a flap pulls no more

    def energy(x):
        a = basis @ x - clearance
        on, eased = np.maximum(a, 0.0), np.clip(a, 0.0, ease)
        flaps = -pull @ (np.minimum(a, 0.0) + eased - 0.5 * eased**2 / ease)
        force = spring * on - pull * (1.0 - eased / ease)
        return 0.5 * spring @ on**2 + flaps - net * x[0] + 0.5 * x @ ridge @ x, basis.T @ force - [net, 0, 0] + ridge @ x

    def hessian(x):
        a = basis @ x - clearance
        stiff = np.where(a > 0, spring, 0.0) + np.where((a > 0) & (a < ease), pull / ease, 0.0)
        return (basis.T * stiff) @ basis + ridge

    start = [touch + near.shift_mm, *near.tilt] if near is not None and not near.lifted else [_settled(clearance, spring, net), 0.0, 0.0]
    x = minimize(energy, np.array(start), jac=True, hess=hessian, method="trust-exact", options={"gtol": 1e-9 * max(net, 1.0)}).x
    return _pressed(basis @ x - clearance, cos, k, cpap_kpa, float(x[0] - touch), x[1:], lifted=False)


def _settled(clearance: np.ndarray, spring: np.ndarray, net: float) -> float:
    """mm: the mask's place along the axis where rim points of (K,) `clearance` mm on (K,) `spring`
    N/mm, none tilted and no flap pulling, carry `net` N (the first touch where it is none): where
    the minimisation starts, so that its first steps are not spent finding the contact."""
    order = np.argsort(clearance, kind="stable")
    c, k = clearance[order], spring[order]
    stiff, moment = np.cumsum(k), np.cumsum(k * c)
    j = max(int(np.searchsorted(stiff * c - moment, net, side="right")) - 1, 0)  # points 0..j touch
    return float(c[0]) if net <= 0 or stiff[j] <= 0 else float((net + moment[j]) / stiff[j])


def _pressed(along, cos, k, cpap_kpa, shift, tilt, lifted) -> Pressed:
    """Pressures and openings from axial indentations `along` (K,) mm."""
    normal = along * cos
    return Pressed(shift, np.asarray(tilt, dtype=float), np.maximum(k * normal, 0.0),
                   np.maximum(cpap_kpa / k - normal, 0.0), lifted)
