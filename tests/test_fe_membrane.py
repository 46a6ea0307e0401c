"""The membrane section by finite elements (geometrically nonlinear, follower pressure, contact with
the skin) against cases with known answers, and what it says of the fast model's reach."""

import numpy as np
import pytest

from cpapfit.evaluation.calibration import root_pull, sealed_opening
from cpapfit.evaluation.fe_checks import elastica_tip, flap_checks, laid_flap
from cpapfit.evaluation.fe_membrane import Flap
from cpapfit.evaluation.membrane import BAND_MM, LARGE, LIFT, ROOT_MM, bending_stiffness, reach_mm, root_pull_kpa_mm

D = bending_stiffness(0.5)  # kPa mm^3: the 0.5 mm flap


def test_the_elastica_reference_is_the_cantilever_under_a_small_load_and_bends_less_under_a_large_one():
    """The boundary-value solution: q L^4 / (8 D) within 1e-4 at a small load; at q = 4 D / L^3 the
    follower pressure's tip deflection is 5-10 % under the linear q L^4 / (8 D) (the tip swings in)."""
    assert -elastica_tip(6.0, D, 1e-5)[1] == pytest.approx(1e-5 * 6.0**4 / (8.0 * D), rel=1e-4)
    large = -elastica_tip(6.0, D, 4.0 * D / 6.0**3)[1]
    assert 0.90 < large / (4.0 * 6.0 / 8.0) < 0.95


def test_a_flap_bends_as_the_plate_under_a_small_pressure_and_as_the_elastica_under_a_large_one():
    """48 x 2 quadratic triangles on a 6 mm, 0.5 mm flap: the small-load tip within 3 % of
    q L^4 / (8 D) (the nearly incompressible section is a little stiff), the large-load tip within
    2 % of the elastica's."""
    small, large = flap_checks()
    assert abs(small.error) < 0.03, small
    assert abs(large.error) < 0.02, large


def test_a_flap_laid_on_the_skin_carries_the_air_pressure_and_balances_it():
    """An 8 mm flap laid by 20 cmH2O on a rigid plane 0.2 mm below its root: where it lies, 2 mm past
    where it touches down and short of its free edge, the skin carries the air pressure (within 2 %:
    the touch-down's concentrated force spreads over a few thicknesses);
    the skin's push and the root's balance the pressure on the flap's deformed air side (within
    1e-6 across the skin, 1 % along it); it touches down within a flap's thickness of the plate's a = (72 D h / q)^(1/4)."""
    p = 20 * 0.0980665
    flap, touchdown = laid_flap(pressure_kpa=p, raised_mm=0.2)
    lying = flap.contact_kpa > 0
    inner = lying & (flap.along > flap.along[lying].min() + 2.0) & (flap.along < 8.0 - 0.5)
    assert flap.contact_kpa[inner].mean() == pytest.approx(p, rel=0.02)
    assert flap.contact_force + flap.root_reaction[1] == pytest.approx(p * (8.0 + flap.tip[0]), rel=1e-6)
    assert flap.root_reaction[0] == pytest.approx(-p * flap.tip[1], rel=0.01)  # the air side drops: it pushes along
    assert 8.0 - flap.lying_mm(p) == pytest.approx(touchdown, abs=0.5)


def test_the_membrane_law_is_the_flap_laid_on_the_skin_by_finite_elements():
    """A flat 5 mm, 0.5 mm flap at 4 cmH2O: the finite elements seal an opening
    of 0.06 mm (lying 2 mm on the skin), the plate laid on a plane a thickness sooner, P a^4 / (72 D)
    with a = w - 2 mm + t, within 0.02 mm; the law for the designed flap takes off its rest lift and
    stand-off (nothing left; an 8 mm flap's drop is short by LARGE drop / a, large deflection), where
    a free cantilever's tip would reach 2.2 mm."""
    p = 4 * 0.0980665
    opening, lying = sealed_opening(Flap(5.0, 0.5, cells=(24, 2)), p, BAND_MM)
    a = 5.0 - BAND_MM + 0.5
    assert lying > 4.5
    assert opening == pytest.approx(p * a**4 / (72.0 * D), abs=0.02)
    drop = p * 6.5**4 / (72.0 * D)
    assert reach_mm(np.array([5.0, 8.0]), np.array([0.5, 0.5]), p) == pytest.approx(
        [0.0, drop * (1.0 - LARGE * drop / 6.5) - LIFT * 6.5 / 3.0 - ROOT_MM], abs=1e-9)
    assert p * 5.0**4 / (8.0 * D) > 2.2


@pytest.mark.parametrize("cmh2o, width, thickness, lies", [(10, 8.0, 0.5, True), (20, 5.0, 0.3, True), (4, 6.0, 0.5, False)])
def test_the_roots_pull_is_the_finite_elements_root_reaction_on_a_designed_flap_at_the_skin(cmh2o, width, thickness, lies):
    """A designed flap (its root ROOT_MM off the skin, rising by LIFT) laid by the CPAP pressure with
    its wall at the skin: where it lies BAND_MM on the skin, the root holds it off the skin with what
    `root_pull_kpa_mm` says (its share of the air's push on the span to where it lies), within 3 %;
    where it lies less (6 mm at 4 cmH2O: 1.1 mm), the law says it pulls nothing (no seal: the air is
    on both sides of it)."""
    p = cmh2o * 0.0980665
    held, lying = root_pull(Flap(width, thickness, ROOT_MM, LIFT, (48, 2)), p)
    law = root_pull_kpa_mm(np.array([width]), np.array([thickness]), p)[0]
    assert (lying >= BAND_MM) == lies
    assert law == (pytest.approx(held, rel=0.03) if lies else 0.0)
