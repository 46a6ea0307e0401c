import numpy as np
import pytest

from cpapfit.errors import UnitsError
from cpapfit.io.units import decide_units


def face_box(extent, n=2000, seed=0):
    """Random points filling a face-shaped box whose largest extent is `extent`."""
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, (n, 3)) * np.array([0.7, 1.0, 0.5]) * extent


@pytest.mark.parametrize("unit,extent", [("mm", 180.0), ("cm", 18.0), ("m", 0.18), ("mm", 75.0), ("m", 0.55), ("um", 180000.0)])
def test_auto_decides_the_unit_that_makes_a_face(unit, extent):
    decided, note = decide_units(face_box(extent))
    assert decided == unit
    assert "decided from the size" in note


@pytest.mark.parametrize("extent", [3.0, 5000.0, 0.001, 5.0e7])
def test_size_that_fits_no_unit_is_refused(extent):
    with pytest.raises(UnitsError, match="none of"):
        decide_units(face_box(extent))


def test_stated_unit_is_checked_for_plausibility():
    assert decide_units(face_box(0.2), "m")[0] == "m"
    with pytest.raises(UnitsError, match="check the unit"):
        decide_units(face_box(0.2), "mm")


def test_outliers_do_not_decide_the_unit():
    pts = face_box(0.16)
    pts[:5] = 50.0  # a few stray points far away (1 % are ignored)
    assert decide_units(pts)[0] == "m"


def test_inches_are_taken_when_stated_and_named_when_auto_could_mistake_them():
    """An 8-inch face: stated, it is inches (25.4 mm each); auto reads it as 8 cm, and says how to state inches."""
    assert decide_units(face_box(8.0), "in")[0] == "in"
    unit, note = decide_units(face_box(8.0))
    assert unit == "cm" and "--units in" in note
    with pytest.raises(UnitsError, match="check the unit"):
        decide_units(face_box(180.0), "in")


@pytest.mark.parametrize("unit,extent", [("mm", 900.0), ("m", 0.9), ("um", 900000.0)])
def test_a_head_and_shoulders_scan_is_taken_in_mm_m_or_um(unit, extent):
    """900 mm across (a bust): auto takes it in mm, m or um, where no unit makes it a face, and says so;
    stated, it is accepted; past 2 m it is no face scan."""
    decided, note = decide_units(face_box(extent))
    assert decided == unit and "head and shoulders" in note
    assert decide_units(face_box(extent), unit)[0] == unit
    with pytest.raises(UnitsError):
        decide_units(face_box(3 * extent), unit)
