"""A cushion's rim on the face as the report takes it: plain arrays, so any evaluation plugs in.

The report reads only these attributes, so an evaluation's own result objects with the same
names can be passed as they are.
"""

from dataclasses import dataclass

import numpy as np

from ..frozen import freeze_arrays

KPA_TO_MMHG = 7.50062


@dataclass(frozen=True)
class RimFit:
    """One cushion's rim seated on the face (scan frame).

    points: (K, 3) mm rim contact line, ordered around the loop (last joins first).
    gap_mm: (K,) mm between rim and skin (0 in contact; NaN where no skin was found).
    pressure_kpa: (K,) kPa contact pressure (0 where open), or None before evaluation.
    open: (K,) bool, the seal is open there (leak), or None before evaluation.
    """

    points: np.ndarray
    gap_mm: np.ndarray
    pressure_kpa: np.ndarray | None = None
    open: np.ndarray | None = None

    def __post_init__(self):
        freeze_arrays(self)


def has_pressure(rims: dict) -> bool:
    """True when every rim of {name: RimFit} carries pressure and open arrays."""
    return all(getattr(r, "pressure_kpa", None) is not None and getattr(r, "open", None) is not None for r in rims.values())
