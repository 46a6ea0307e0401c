"""The seal flange as a beam along the rim (`mechanics.press` with bending): against Hetenyi's
beam on an elastic foundation, and against each point on its own spring without bending."""

import numpy as np
import pytest
from scipy.optimize import minimize

from cpapfit.cushion.nurbs import CushionParams
from cpapfit.evaluation.fit import FitParams, flange_rigidity
from cpapfit.evaluation.mechanics import COS_MIN, N_PER_KPA_MM2, Flange, press

WIDTH_MM = 5.0
EI = flange_rigidity(WIDTH_MM, 2.0)  # N mm^2: the 5 mm flange of the 2 mm wall


def ring(k_points: int, step_mm: float) -> np.ndarray:
    """(K, 2) mm points of a circle K steps of `step_mm` round."""
    t = 2 * np.pi * np.arange(k_points) / k_points
    return k_points * step_mm / (2 * np.pi) * np.column_stack([np.cos(t), np.sin(t)])


def test_flange_rigidity_is_a_silicone_strip_bent_through_its_thickness():
    assert EI == pytest.approx(1.0 * 5.0 * 2.0**3 / 12)  # E 1 MPa = 1 N/mm^2
    assert FitParams().flange_rigidity_n_mm2(WIDTH_MM) == 0.0
    assert FitParams(flange_thickness_mm=CushionParams().wall_mm).flange_rigidity_n_mm2(WIDTH_MM) == pytest.approx(EI)


def test_a_point_load_bends_the_flange_as_hetenyis_beam_on_an_elastic_foundation():
    """One rim point over skin, the rest over none: the whole load enters the flange there and the
    flange spring holds it along the rim, w(x) = P beta / (2 k) e^(-beta x) (cos beta x + sin beta x),
    beta = (k / 4 EI)^(1/4), k the foundation per mm of rim (a rim 200 mm round is long beside 1/beta)."""
    k_points, step, spring, load = 2000, 0.1, 1.0, 1.0
    clearance = np.full(k_points, np.nan)
    clearance[0] = 0.0
    pressed = press(clearance, np.ones(k_points), np.full(k_points, WIDTH_MM * step), np.full(k_points, 10.0), ring(k_points, step),
                    100.0, load, 0.0, Flange(spring, EI, np.full(k_points, step)))
    foundation = spring * WIDTH_MM * N_PER_KPA_MM2  # N/mm per mm of rim
    beta = (foundation / (4 * EI)) ** 0.25
    x = step * np.minimum(np.arange(k_points), k_points - np.arange(k_points))
    hetenyi = load * beta / (2 * foundation) * np.exp(-beta * x) * (np.cos(beta * x) + np.sin(beta * x))
    w = pressed.flange_mm
    assert 1 / beta == pytest.approx(7.2, abs=0.1)  # the bending length on the flange spring, mm
    assert w[0] == pytest.approx(hetenyi[0], rel=0.01)
    assert np.abs(w - hetenyi).max() < 0.01 * hetenyi[0]
    first_zero = x[:k_points // 2][np.argmax(w[:k_points // 2] < 0)]
    assert first_zero == pytest.approx(3 * np.pi / (4 * beta), rel=0.02)
    assert (foundation * step * w).sum() == pytest.approx(load, rel=1e-6)  # the flange spring carries the load


def winkler(clearance, cos, area, k, spring, uv, sealed, force):
    """The rim with each covered point its own spring, skin and flange in series: the pose minimising
    sum 1/2 k_eff A cos^2 max(a, 0)^2 - net d, found by scipy on the three pose unknowns."""
    on = np.isfinite(clearance)
    cos = np.maximum(cos, COS_MIN)[on]
    axial = 1.0 / (1.0 / k + 1.0 / spring)[on] * area[on] * cos**2 * N_PER_KPA_MM2
    centre = (area[on] * cos) @ uv[on] / (area[on] @ cos)
    basis = np.column_stack([np.ones(on.sum()), uv[on] - centre])

    def energy(x):
        a = np.maximum(basis @ x - clearance[on], 0.0)
        return 0.5 * axial @ a**2 - force * x[0], basis.T @ (axial * a) - [force, 0, 0]

    x = minimize(energy, [clearance[on].min() + 1.0, 0, 0], jac=True, method="BFGS", options={"gtol": 1e-12}).x
    return 1.0 / (1.0 / k + 1.0 / spring)[on] * np.maximum(basis @ x - clearance[on], 0.0) * cos


@pytest.mark.parametrize("rigidity", [0.0, 1e-12])
def test_without_bending_each_rim_point_is_its_own_spring(rigidity):
    rng = np.random.default_rng(5)
    k_points = 256
    uv = ring(k_points, 0.7) * [1.0, 0.8]
    clearance, cos, k = rng.uniform(0.0, 1.5, k_points), rng.uniform(0.3, 1.0, k_points), rng.uniform(4.0, 46.0, k_points)
    clearance[40:60] = np.nan  # a stretch of the rim over no scanned skin
    area = WIDTH_MM * rng.uniform(0.5, 0.9, k_points)
    steps = np.linalg.norm(np.roll(uv, -1, axis=0) - uv, axis=1)
    pressed = press(clearance, cos, area, k, uv, 0.0, 6.0, 0.0, Flange(1.0, rigidity, steps))
    assert pressed.pressure_kpa == pytest.approx(winkler(clearance, cos, area, k, np.full(k_points, 1.0), uv, 0.0, 6.0), abs=1e-6)


def test_a_uniform_rim_presses_uniformly_with_the_beam_on_uneven_steps():
    rng = np.random.default_rng(2)
    k_points = 256
    t = np.sort(rng.uniform(0, 2 * np.pi, k_points))
    uv = 30.0 * np.column_stack([np.cos(t), np.sin(t)])
    steps = np.linalg.norm(np.roll(uv, -1, axis=0) - uv, axis=1)
    area = WIDTH_MM * 0.5 * (steps + np.roll(steps, 1))
    clearance = 0.05 * uv[:, 0]  # the face falls away 5 % towards +u: the mask tilts, the flange stays straight
    pressed = press(clearance, np.ones(k_points), area, np.full(k_points, 10.0), uv, 0.0, 8.0, 0.0, Flange(1.0, EI, steps))
    assert pressed.pressure_kpa == pytest.approx(np.full(k_points, 8.0 / area.sum() / N_PER_KPA_MM2), rel=1e-6)
    assert np.ptp(pressed.flange_mm) < 1e-8 * pressed.flange_mm.mean()
