"""The finite-element reference against cases with known answers, and the calibration's springs."""

import numpy as np
import pytest

from cpapfit.evaluation.calibration import section_stiffness, strip_stiffness
from cpapfit.evaluation.fe import Material
from cpapfit.evaluation.fe_checks import confined_layer_check, hertz_checks, plate_checks
from cpapfit.evaluation.tissue import REGIONS, STRIP_MM
from cpapfit.cushion.nurbs import CushionParams


def test_plates_under_pressure_bend_as_plate_theory_says():
    """Cantilever tip and clamped strip middle within 3 % (shear adds a little to a 20:1 plate)."""
    for check in plate_checks():
        assert abs(check.error) < 0.03, check


def test_a_rigid_cylinder_pressed_into_a_block_makes_the_hertz_contact():
    """Half-width within 5 % (the coarse mesh's step is 7 % of it); the elliptic pressure's share inside
    half the width (0.609) within 0.02."""
    width, share = hertz_checks()
    assert abs(width.error) < 0.05, width
    assert share.computed == pytest.approx(share.expected, abs=0.02)


def test_a_wide_strip_on_a_thin_layer_presses_it_as_a_confined_column():
    check = confined_layer_check()
    assert abs(check.error) < 0.03, check


@pytest.mark.parametrize("region", list(REGIONS))
def test_the_fit_models_tissue_springs_are_the_finite_element_layers_under_the_flange(region):
    """Each region's spring is what the finite elements give for its layer (E, depth, Poisson 0.49)
    under a strip as wide as the flange, within 2 % on a coarse mesh: 3-4 times E / h."""
    e, h, k, _ = REGIONS[region]
    assert STRIP_MM == CushionParams().flange_mm
    assert strip_stiffness(e, h, STRIP_MM, cells=12) == pytest.approx(k, rel=0.02)
    assert 3.0 < k / (e / h) < 4.2


def arched_wall() -> np.ndarray:
    """(P, 2) mm: a flange 5 mm across the axis, a 4 mm bend, a wall rising to 25 mm (across, along the axis)."""
    turn = np.linspace(0.0, np.pi / 2, 20)
    return np.vstack([np.column_stack([np.linspace(0.0, 5.0, 10), np.zeros(10)]),
                      np.column_stack([5.0 + 4.0 * np.sin(turn[1:]), 4.0 - 4.0 * np.cos(turn[1:])]),
                      np.column_stack([np.full(20, 9.0), np.linspace(4.5, 25.0, 20)])])


def test_a_cushion_wall_grips_harder_than_it_slides():
    """An arched wall (flange across the axis, then rising 25 mm, the flange 4 mm off the wall's line):
    bonded to the skin it is stiffer than sliding on it, and either is softer than the wall as a
    straight column would be (E* t / H over the flange: the arch bends)."""
    profile = arched_wall()
    sliding, bonded = section_stiffness(profile, 2.0, 5.0), section_stiffness(profile, 2.0, 5.0, bonded=True)
    assert 0.0 < sliding < bonded < Material().plane_strain_kpa * 2.0 / 25.0 / 5.0


def test_a_sliding_flange_presses_alike_whichever_way_its_skin_tilts():
    """The same wall turned 15 degrees about the rim (the skin sloping under the flange): pushed along
    the axis, a frictionless flange's stiffness changes only by the slope's geometry (cos^2 15 deg of
    the level one within 15 %), not by friction the contact would add if it pushed straight down."""
    profile = arched_wall()
    tilt = np.radians(15.0)
    tilted = profile @ np.array([[np.cos(tilt), np.sin(tilt)], [-np.sin(tilt), np.cos(tilt)]])
    level, sloped = section_stiffness(profile, 2.0, 5.0), section_stiffness(tilted, 2.0, 5.0)
    assert sloped == pytest.approx(level * np.cos(tilt) ** 2, rel=0.15)


def test_a_flange_along_the_axis_cannot_be_pressed_along_it():
    with pytest.raises(ValueError, match="along the mask axis"):
        section_stiffness(np.column_stack([np.zeros(20), np.linspace(0.0, 20.0, 20)]), 2.0, 5.0)
