"""Units of a mesh scan: stated by the user or decided from the size of the face."""

import numpy as np

from ..errors import UnitsError
from ..scan import robust_extent
from ..thresholds import BUST_EXTENT_MM, FACE_EXTENT_MM

MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "um": 0.001, "in": 25.4}
UNIT_NAMES = {"mm": "millimetres", "cm": "centimetres", "m": "metres", "um": "micrometres", "in": "inches"}
# Micrometres: the Basel Face Model and scans fitted with it. A face in inches is a face in
# centimetres too: inches must be stated.
AUTO_UNITS = ("mm", "cm", "m", "um")
UNIT_CHOICES = ("auto", *MM_PER_UNIT)  # what --units takes
BUST_UNITS = ("mm", "m", "um")


def _fits(extent: float, unit: str, extent_mm: tuple[float, float] = FACE_EXTENT_MM) -> bool:
    size = extent * MM_PER_UNIT[unit]
    return extent_mm[0] <= size <= extent_mm[1]


def decide_units(vertices: np.ndarray, stated: str = "auto") -> tuple[str, str]:
    """The unit of (N, 3) vertices and a sentence saying how it was decided.

    `stated` is "auto" or one of MM_PER_UNIT. Auto picks the one of AUTO_UNITS in which the scan's
    robust extent is the size of a face (70-600 mm; their ranges do not overlap), else the one of
    BUST_UNITS in which it is the size of a head and shoulders (600-2000 mm). A stated unit that
    makes the scan smaller than a face or larger than a bust is refused, as is a scan no unit fits.
    """
    extent = robust_extent(vertices)
    lo, hi = FACE_EXTENT_MM
    if stated != "auto":
        if stated not in MM_PER_UNIT:
            raise UnitsError(f"unknown unit '{stated}': use {', '.join(UNIT_CHOICES)}")
        if not _fits(extent, stated, (lo, BUST_EXTENT_MM[1])):
            size = extent * MM_PER_UNIT[stated]
            raise UnitsError(
                f"in {UNIT_NAMES[stated]} the scan is {size:.4g} mm across, but a face is {lo:.0f}-{hi:.0f} mm (with the "
                f"shoulders up to {BUST_EXTENT_MM[1]:.0f}): check the unit (--units {'|'.join(MM_PER_UNIT)}) or use --units auto"
                + ("; crop a scan of more than head and shoulders to the head" if size > BUST_EXTENT_MM[1] else "")
            )
        return stated, f"units: {UNIT_NAMES[stated]} as stated ({extent * MM_PER_UNIT[stated]:.0f} mm across)"
    for unit in AUTO_UNITS:
        if _fits(extent, unit):
            size = extent * MM_PER_UNIT[unit]
            inches = " (a scan in inches: state --units in)" if unit == "cm" else ""
            return unit, f"units: {UNIT_NAMES[unit]}, decided from the size ({extent:.4g} {unit} = {size:.0f} mm across){inches}"
    for unit in BUST_UNITS:
        if _fits(extent, unit, BUST_EXTENT_MM):
            size = extent * MM_PER_UNIT[unit]
            return unit, (f"units: {UNIT_NAMES[unit]}, decided from the size ({extent:.4g} {unit} = {size:.0f} mm across: "
                          "more than a face, e.g. head and shoulders)")
    raise UnitsError(
        f"the scan is {extent:.4g} units across, which is the size of a face ({lo:.0f}-{hi:.0f} mm, with the shoulders up to "
        f"{BUST_EXTENT_MM[1]:.0f} mm) in none of mm, cm, m or um: is it a face scan? state the unit with --units ({', '.join(MM_PER_UNIT)}), "
        "or crop a scan of more than head and shoulders to the head"
    )
