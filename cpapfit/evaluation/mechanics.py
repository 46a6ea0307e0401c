"""The mask as a rigid body on an elastic face, through a seal flange that bends along the rim:
equilibrium under headgear and CPAP.

Rim point i (K of them, a closed loop) is pushed along the mask axis by a_i = d + tilt . uv_i -
clearance_i (mm; d the mask's shift towards the face, tilt (2,) its slopes across the axis). The
seal flange there gives by w_i (mm, along the axis, relative to the rigid mask) against the wall
behind it (the flange spring, c_i = k_flange A_i cos_i^2 N/mm along the axis), and the skin is
indented by e_i = a_i - w_i along the axis, e_i cos_i along its normal, pressing back with
p_i = k_i e_i cos_i (kPa) over A_i = flange width * ds_i (the skin spring s_i = k_i A_i cos_i^2,
one-sided: no pull where e_i < 0). Along the rim the flange is a beam of bending rigidity EI (N mm^2)
on these two foundations (Hetenyi): its energy 1/2 EI sum_i kappa_i^2 ds_i, kappa_i the second
difference of w over the steps to the neighbours (uneven steps allowed). Where the rim is not over
scanned skin the beam and its flange spring go on, with no skin under them. The headgear force F (N)
pushes along the axis through the centroid of the covered contact band (weighted by A_i cos_i); the
CPAP pressure P over the sealed area pushes the mask off, taken through the same line. The
equilibrium minimises the convex energy
    sum_i 1/2 s_i max(e_i, 0)^2 + 1/2 c_i w_i^2 + 1/2 EI sum_i kappa_i^2 ds_i - (F - P * sealed area) * d
over (d, tilt, w): force balance along the axis, moment balance about the two axes across it, and
each point's balance of skin, flange spring and beam. With EI = 0 each point is its own spring, the
skin and the flange in series. Where p_i < P the air lifts the seal open by (P - p_i) / k_eff,
k_eff the two in series, plus any gap left between flange and skin (normal, mm).
"""

from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_banded

from ..frozen import freeze_arrays

COS_MIN = 0.2  # skin steeper than ~78 degrees to the axis is treated as 78 degrees
N_PER_KPA_MM2 = 1e-3
MAX_STEPS = 200  # Newton steps; each settles the contact set further (a handful in practice)


@dataclass(frozen=True)
class Flange:
    """The seal flange along a closed rim of K >= 5 points: spring_kpa_per_mm its give per unit contact
    area against the wall behind it; rigidity_n_mm2 its bending rigidity EI along the rim (0: each
    point on its own); step_mm (K,) distance from each rim point to the next."""

    spring_kpa_per_mm: float
    rigidity_n_mm2: float
    step_mm: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)

    def bending(self) -> np.ndarray:
        """(3, K) the beam's energy 1/2 w' B w (N mm) of deflections w (K,) mm, B = EI D' diag(ds) D with D
        the second difference over uneven steps around the loop (1/mm^2), by its diagonals: B[j, j],
        B[j, j+1], B[j, j+2] (indices round the loop)."""
        ahead = np.maximum(self.step_mm, 1e-6)
        back = np.roll(ahead, 1)  # step from the previous point
        ds = 0.5 * (ahead + back)
        prev, mid, nxt = 1.0 / (back * ds), -(1.0 / back + 1.0 / ahead) / ds, 1.0 / (ahead * ds)  # row i of D: columns i-1, i, i+1
        on = np.roll(ds * prev**2, -1) + ds * mid**2 + np.roll(ds * nxt**2, 1)
        one = ds * mid * nxt + np.roll(ds * prev * mid, -1)
        two = np.roll(ds * prev * nxt, -1)
        return self.rigidity_n_mm2 * np.stack([on, one, two])


@dataclass(frozen=True)
class Pressed:
    """The mask at equilibrium: shift_mm along the axis (from first touch), tilt (2,) slopes;
    pressure_kpa (K_c,) contact pressure on the skin and opening_mm (K_c,) seal opening (0: closed)
    at the K_c covered rim points; flange_mm (K,) the flange's give along the axis at every rim
    point; lifted: the CPAP load exceeds the headgear force (no contact can hold)."""

    shift_mm: float
    tilt: np.ndarray
    pressure_kpa: np.ndarray
    opening_mm: np.ndarray
    flange_mm: np.ndarray
    lifted: bool

    def __post_init__(self):
        freeze_arrays(self)


def press(clearance, cos, area_mm2, k, uv, sealed_area_mm2: float, force_n: float, cpap_kpa: float, flange: Flange,
          start: Pressed | None = None) -> Pressed:
    """Equilibrium of a closed rim of K points (arrays (K,), uv (K, 2); clearance NaN where the rim is
    not over scanned skin) under `force_n` N of headgear and `cpap_kpa` over `sealed_area_mm2`; k (K,)
    kPa/mm the skin's normal stiffness, `flange` the seal flange between it and the rigid mask;
    `start`: the same rim's equilibrium under another load, where the search begins (same result)."""
    on = np.isfinite(clearance)
    cos = np.maximum(cos, COS_MIN)
    axial = area_mm2 * cos**2 * N_PER_KPA_MM2  # N/mm along the axis per kPa/mm
    net = force_n - cpap_kpa * sealed_area_mm2 * N_PER_KPA_MM2
    centre = (area_mm2 * cos)[on] @ uv[on] / (area_mm2 @ (cos * on))  # the load's line of action: the covered band's centroid
    basis = np.column_stack([np.ones(len(cos)), uv - centre])
    touch = float(clearance[on].min())
    series = 1.0 / (1.0 / k + 1.0 / flange.spring_kpa_per_mm)
    if net <= 0:
        return _pressed(touch - clearance[on], cos[on], k[on], series[on], cpap_kpa, 0.0, np.zeros(2), np.zeros(len(cos)), lifted=True)
    skin = np.where(on, k * axial, 0.0)
    ridge = 1e-9 * float((series * axial)[on].sum()) * np.diag([0.0, *np.mean(uv**2, axis=0)])  # pins the tilt of a rim touching at one point
    begin = (np.array([touch, 0.0, 0.0]), None) if start is None or start.lifted else (np.r_[start.shift_mm + touch, start.tilt], start.flange_mm)
    x, w = _equilibrium(basis, np.where(on, clearance, 0.0), skin, flange.spring_kpa_per_mm * axial, flange.bending(), net, ridge, *begin)
    return _pressed((basis @ x - w - clearance)[on], cos[on], k[on], series[on], cpap_kpa, float(x[0] - touch), x[1:], w, lifted=False)


def _equilibrium(basis, clearance, skin, spring, bend, net, ridge, x, w):
    """The minimiser (pose x (3,), flange give w (K,)) of the module's energy from the pose `x` and give
    `w` (None: none, every covered point taken to touch, as on a pressed rim), by Newton steps on its
    piecewise-quadratic form (the contact set of the last iterate, an exact line search after the
    first): exact once the contact set settles. `skin` is 0 where the rim is not covered; `bend`
    (3, K) the beam's diagonals."""
    covered = skin > 0
    touching = skin if w is None else np.where(basis @ x - w - clearance >= 0, skin, 0.0)
    w = np.zeros(len(skin)) if w is None else w
    solve = _loop_solver(bend)
    for step in range(MAX_STEPS):
        e = basis @ x - w - clearance
        force, elastic = touching * e, spring * w + _times(bend, w)
        gx = basis.T @ force - [net, 0.0, 0.0] + ridge @ x
        solved = solve(spring + touching, np.column_stack([basis * touching[:, None], elastic - force]))
        schur = (basis.T * touching) @ basis + ridge - (basis.T * touching) @ solved[:, :3]
        dx = np.linalg.solve(schur, -gx - (basis.T * touching) @ solved[:, 3])
        dw = solved[:, :3] @ dx - solved[:, 3]
        de = basis @ dx - dw
        if np.array_equal((e + de >= 0) & covered, touching > 0):  # this piece's minimum lies in it: the energy's
            return x + dx, w + dw
        if step:
            line = (dw @ elastic - net * dx[0] + x @ ridge @ dx, dw @ (spring * dw + _times(bend, dw)) + dx @ ridge @ dx)
            dx, dw = (_line_minimum(e, de, skin, *line) * d for d in (dx, dw))
        x, w = x + dx, w + dw
        e = basis @ x - w - clearance
        if not (e >= 0)[covered].any():  # off the face: move in until the nearest point touches
            x[0] -= e[covered].max()
            e = basis @ x - w - clearance
        touching = np.where(e >= 0, skin, 0.0)
    return x, w


def _line_minimum(e, de, skin, slope, curvature) -> float:
    """The t > 0 minimising a convex piecewise quadratic along a descent direction, with derivative
    slope + t curvature + sum_i skin_i de_i max(e_i + t de_i, 0): found between its breakpoints."""
    def derivative(t):
        return slope + t * curvature + (skin * de * np.maximum(e + np.multiply.outer(t, de), 0.0)).sum(axis=-1)

    with np.errstate(divide="ignore", invalid="ignore"):
        cut = -e / de
    cut = np.sort(cut[np.isfinite(cut) & (cut > 0)])
    after = np.searchsorted(derivative(cut) >= 0, True)  # the first breakpoint past the minimum
    lo = cut[after - 1] if after > 0 else 0.0
    hi = cut[after] if after < len(cut) else lo + 1.0  # the last piece is a quadratic: any point past lo
    d_lo, d_hi = derivative(lo), derivative(hi)
    return float(lo - d_lo * (hi - lo) / (d_hi - d_lo))


def _times(bend: np.ndarray, w: np.ndarray) -> np.ndarray:
    """B w (K,) of the beam's matrix by its diagonals `bend` (3, K) (`Flange.bending`)."""
    on, one, two = bend
    a, b = one * w, two * w
    cat = np.concatenate
    return on * w + one * cat((w[1:], w[:1])) + cat((a[-1:], a[:-1])) + two * cat((w[2:], w[:2])) + cat((b[-2:], b[:-2]))


def _loop_solver(bend: np.ndarray):
    """solve(diagonal (K,), rhs (K, m)) -> (B + diag(diagonal))^-1 rhs for the closed loop's
    pentadiagonal B (`bend` (3, K), its diagonals): a banded solve of the open band and the four
    corner terms that close the loop, by the Woodbury identity."""
    on, one, two = bend
    k = len(on)
    band = np.zeros((5, k))  # rows: B[j-2, j], B[j-1, j], B[j, j], B[j+1, j], B[j+2, j] of the open band
    band[0, 2:], band[1, 1:], band[2], band[3, :-1], band[4, :-2] = two[:-2], one[:-1], on, one[:-1], two[:-2]
    ends = np.array([0, 1, k - 2, k - 1])
    corner = np.zeros((4, 4))
    corner[:2, 2:] = [[two[k - 2], one[k - 1]], [0.0, two[k - 1]]]  # B[0, k-2], B[0, k-1]; B[1, k-2], B[1, k-1]
    corner[2:, :2] = corner[:2, 2:].T
    unit = np.zeros((k, 4))
    unit[ends, np.arange(4)] = 1.0

    def solve(diagonal: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        ab = band.copy()
        ab[2] += diagonal
        out = solve_banded((2, 2), ab, np.column_stack([unit, rhs]), check_finite=False)
        y, z = out[:, :4], out[:, 4:]
        return z - y @ np.linalg.solve(np.eye(4) + corner @ y[ends], corner @ z[ends])

    return solve


def _pressed(along, cos, k, series, cpap_kpa, shift, tilt, flange, lifted) -> Pressed:
    """Pressures and openings from the skin's axial indentations `along` (K_c,) mm."""
    normal = along * cos
    pressure = np.maximum(k * normal, 0.0)
    return Pressed(shift, np.asarray(tilt, dtype=float), pressure,
                   np.maximum((cpap_kpa - pressure) / series - np.minimum(normal, 0.0), 0.0), flange, lifted)
