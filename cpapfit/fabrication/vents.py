"""The exhaust vents (CO2 washout) sized by the orifice law to a stock nasal mask's vent curve.

Each hole passes Q = Cd A sqrt(2 dP / rho) (`evaluation.leak.orifice_l_min`: Cd 0.6, a sharp-edged
orifice; air 1.2 kg/m3). The model assumes fully developed orifice flow through every hole, no
interaction between holes and no loss in the short hole itself (the frame wall is 2 mm, under two
hole diameters); a hole whose edge is rounded passes more (Cd up to ~0.8), so a printed frame's
vent flow is to be measured before use.
"""

from dataclasses import dataclass

import numpy as np

from ..evaluation.fit import KPA_PER_CMH2O
from ..evaluation.leak import DISCHARGE_COEFFICIENT, orifice_l_min

TARGET_CMH2O = (4.0, 8.0, 12.0, 16.0, 20.0)
TARGET_L_MIN = (19.0, 28.0, 34.0, 40.0, 45.0)  # a stock nasal mask's vent flow at those pressures
HOLE_MM = 1.2  # diameter of each vent hole
REPORTED_CMH2O = (4.0, 10.0, 20.0)


@dataclass(frozen=True)
class Vents:
    """`count` round holes of `diameter_mm` mm."""

    count: int
    diameter_mm: float

    def flow_l_min(self, cmh2o) -> np.ndarray:
        """The vents' total flow (L/min) at each pressure of `cmh2o` (cmH2O): the orifice law."""
        area_mm2 = self.count * np.pi * self.diameter_mm**2 / 4.0
        return orifice_l_min(np.asarray(area_mm2, dtype=float), 1.0, np.asarray(cmh2o, dtype=float) * KPA_PER_CMH2O)

    def worst_error(self) -> float:
        """The largest relative error (fraction) of the flow against the target curve."""
        return float(np.max(np.abs(self.flow_l_min(TARGET_CMH2O) / np.asarray(TARGET_L_MIN) - 1.0)))

    def record(self) -> dict:
        """mask.json's vents: holes, flow at REPORTED_CMH2O, the target and the model."""
        return {
            "count": self.count, "diameter_mm": self.diameter_mm,
            "flow_l_min": {f"{p:g}_cmh2o": round(float(q), 2) for p, q in zip(REPORTED_CMH2O, self.flow_l_min(REPORTED_CMH2O))},
            "target_l_min": {f"{p:g}_cmh2o": q for p, q in zip(TARGET_CMH2O, TARGET_L_MIN)},
            "worst_error_fraction": round(self.worst_error(), 4),
            "model": f"orifice law Q = Cd A sqrt(2 dP / rho) per hole, Cd {DISCHARGE_COEFFICIENT:g} (sharp-edged), no interaction "
                     "between holes; a rounded hole edge passes more: measure the printed frame's flow",
        }


def sized_vents(diameter_mm: float = HOLE_MM) -> Vents:
    """The number of `diameter_mm` holes whose flow is nearest the target curve (least worst relative error)."""
    one = Vents(1, diameter_mm).flow_l_min(TARGET_CMH2O)
    best = np.sqrt(np.min(TARGET_L_MIN / one) * np.max(TARGET_L_MIN / one))  # equal worst error above and below, in ratio
    return min((Vents(n, diameter_mm) for n in (int(np.floor(best)), int(np.ceil(best)))), key=Vents.worst_error)
