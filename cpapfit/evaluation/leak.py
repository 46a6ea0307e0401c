"""Leak through an open seal: thin-film (lubrication) flow across the seal flange, limited by
orifice flow where the gap is wide.

A gap of height h (normal to the skin) over a rim length ds, with the CPAP pressure dp driving
air across a flange of width L, passes h^3 * dp * ds / (12 mu L) (plane Poiseuille flow, the
gap^3 law) while that flow stays laminar and viscous; a wide gap cannot pass more than an
orifice of the same opening, Cd * h * ds * sqrt(2 dp / rho). The smaller of the two is taken.
"""

import numpy as np

AIR_VISCOSITY_PA_S = 1.8e-5  # at ~20-30 C
AIR_DENSITY_KG_M3 = 1.2
DISCHARGE_COEFFICIENT = 0.6  # sharp-edged orifice
M3_S_TO_L_MIN = 6e4


def lubrication_l_min(opening_mm: np.ndarray, ds_mm: np.ndarray, path_mm: float, dp_kpa: float) -> np.ndarray:
    """(K,) L/min of viscous flow through gaps `opening_mm` (K,) along rim lengths `ds_mm` (K,)."""
    h, ds, path, dp = opening_mm * 1e-3, ds_mm * 1e-3, path_mm * 1e-3, dp_kpa * 1e3
    return h**3 * dp * ds / (12.0 * AIR_VISCOSITY_PA_S * path) * M3_S_TO_L_MIN


def orifice_l_min(opening_mm: np.ndarray, ds_mm: np.ndarray, dp_kpa: float) -> np.ndarray:
    """(K,) L/min through sharp-edged openings of area opening_mm * ds_mm at pressure dp_kpa."""
    area = opening_mm * ds_mm * 1e-6
    return DISCHARGE_COEFFICIENT * area * np.sqrt(2.0 * dp_kpa * 1e3 / AIR_DENSITY_KG_M3) * M3_S_TO_L_MIN


def leak_l_min(opening_mm: np.ndarray, ds_mm: np.ndarray, path_mm: float, dp_kpa: float) -> np.ndarray:
    """(K,) L/min leaking at each rim point: the lesser of viscous and orifice flow."""
    return np.minimum(lubrication_l_min(opening_mm, ds_mm, path_mm, dp_kpa), orifice_l_min(opening_mm, ds_mm, dp_kpa))
