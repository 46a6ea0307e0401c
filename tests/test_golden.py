"""Golden figures: the headline numbers of the three synthetic designs the suite makes (`designed`:
seed 3 with both masks, seed 2 oronasal; `tests/golden_fit.json`), so that a change that moves a
figure is seen. A change meant to move them rewrites that file and says why in its commit."""

import json
from pathlib import Path

import pytest

from cpapfit.records import design_record

GOLDEN = json.loads((Path(__file__).resolve().parent / "golden_fit.json").read_text())
TOLERANCE = {  # how far a figure may move (its unit) before the change is a change of figures
    "residual_median_mm": 0.002, "rim_gap_median_mm": 0.002, "headgear_force_n": 0.01, "pressure_mean_kpa": 0.005,
    # the peak of 256 rim points, which the capture's depth noise makes jagged (seed 2's oronasal: 2.5-2.85 kPa
    # 1 mm apart): a 1e-4 mm change of the registration moved it from 2.85 to 2.99 kPa in one of 18 trials
    # (RESULTS section 8; the golden file holds seed 2's at 2.89 kPa)
    "pressure_max_kpa": 0.2,
    "window_fraction": 0.005, "leak_l_min": 0.01,
    # the stock size's peak at 1.1 times its seal force (a 0.01 N bisection), on a registration that another
    # CPU or BLAS thread count moves by up to 0.03 mm: 2.319 / 2.336 kPa on two machines, up to 0.03 kPa apart
    # between thread counts (RESULTS section 8)
    "stock_pressure_max_kpa": 0.05,
}
WHERE = {"residual_median_mm": ("registration", "residual_median_mm"), "rim_gap_median_mm": ("fit_before_compression", "rim_gap_median_mm"),
         "headgear_force_n": ("custom", "headgear_force_n"), "pressure_max_kpa": ("custom", "pressure_max_kpa"),
         "pressure_mean_kpa": ("custom", "pressure_mean_kpa"),
         "window_fraction": ("custom", "window_fraction"), "leak_l_min": ("custom", "leak_l_min"),
         "stock_size": ("stock_fitting", "size"), "stock_pressure_max_kpa": ("stock", "pressure_max_kpa")}


def test_the_designs_headline_figures_are_the_golden_ones(designed, placed_subjects):
    ph, d = designed
    record = design_record(d, placed_subjects(ph.seed)[1])
    golden = GOLDEN[f"{ph.seed} {d.contact.mask}"]
    for key, (part, name) in WHERE.items():
        if key in TOLERANCE:
            assert record[part][name] == pytest.approx(golden[key], abs=TOLERANCE[key]), key
        else:
            assert record[part][name] == golden[key], key
