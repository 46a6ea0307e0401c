"""The table of quality gates in docs/quality_gates.md states the thresholds `QualityParams` holds."""

import re
from pathlib import Path

import pytest

from cpapfit.thresholds import QualityParams

GATES_PAGE = Path(__file__).resolve().parent.parent / "docs" / "quality_gates.md"
# (gate code, words its row starts with) -> the QualityParams fields of its (flagged, refused) thresholds
ROWS = {
    ("coverage", ""): ("coverage_flag", "coverage_refuse"),
    ("hole_mm", ""): ("hole_flag_mm", "hole_refuse_mm"),
    ("residual_mm", ""): ("residual_flag_mm", "residual_refuse_mm"),
    ("landmarks_mm", ""): ("landmarks_flag_mm", "landmarks_refuse_mm"),
    ("landmark_spread_mm", "a landmarks file"): ("landmark_spread_flag_mm", "landmark_spread_refuse_mm"),
    ("landmark_spread_mm", "detected landmarks"): ("detected_spread_flag_mm", "detected_spread_refuse_mm"),
    ("rim_gap_mm", ""): ("rim_gap_flag_mm", "rim_gap_refuse_mm"),
    ("shape_apart_mm", ""): ("shape_apart_flag_mm", "shape_apart_refuse_mm"),
    ("face_size", "smaller"): ("small_face_flag", "small_face_refuse"),
    ("face_size", "larger"): ("large_face_flag", "large_face_refuse"),
    ("depth_ratio", "flatter"): ("flat_face_flag", "flat_face_refuse"),
    ("depth_ratio", "deeper"): ("deep_face_flag", "deep_face_refuse"),
    ("lips_apart_mm", ""): ("lips_apart_flag_mm", "lips_apart_refuse_mm"),
    ("in_front_mm2", ""): ("in_front_flag_mm2", "in_front_refuse_mm2"),
}
ALWAYS_FLAGGED = ("landmark_free",)  # no threshold: flagged whenever it happens, never refused


def table() -> list[list[str]]:
    """The cells of each row of the gate table: code, measure, flagged, refused."""
    rows = [re.match(r"\| `(\w+)` \| (.*) \| (.*) \| (.*) \|$", line) for line in GATES_PAGE.read_text().splitlines()]
    return [list(m.groups()) for m in rows if m and m.group(1) in {code for code, _ in ROWS} | set(ALWAYS_FLAGGED)]


def gate_rows() -> list[tuple[str, str, float, float]]:
    """(code, measure, flagged at, refused at) of each thresholded row (% as fractions)."""
    rows = []
    for code, measure, flag, refuse in table():
        if code not in ALWAYS_FLAGGED:
            rows.append((code, measure, *map(threshold, (flag, refuse))))
    return rows


def threshold(cell: str) -> float:
    """A table cell's threshold: "> 2 mm" is 2, "< 75 %" 0.75, "never" infinite."""
    if cell == "never":
        return float("inf")
    m = re.fullmatch(r"[<>] ([\d.]+) (%|mm²|mm)", cell)
    return float(m.group(1)) * (0.01 if m.group(2) == "%" else 1.0)


def row_key(code: str, measure: str) -> tuple[str, str]:
    """The ROWS key of a table row: its code and the words its measure starts with, if its code has several rows."""
    return code, next((w for c, w in ROWS if c == code and w and measure.startswith(w)), "")


def test_every_gate_has_one_row():
    assert sorted(row_key(code, measure) for code, measure, *_ in gate_rows()) == sorted(ROWS)
    assert [cells[2:] for cells in table() if cells[0] in ALWAYS_FLAGGED] == [["always", "never"]]


def test_every_threshold_is_in_the_table():
    fields = {f for f in vars(QualityParams()) if f.endswith(("_flag", "_refuse", "_flag_mm", "_refuse_mm", "_flag_mm2", "_refuse_mm2"))}
    assert fields == {f for pair in ROWS.values() for f in pair}


@pytest.mark.parametrize("code,measure,flag,refuse", gate_rows())
def test_the_readme_states_the_thresholds_in_force(code, measure, flag, refuse):
    flag_field, refuse_field = ROWS[row_key(code, measure)]
    params = QualityParams()
    assert (flag, refuse) == pytest.approx((getattr(params, flag_field), getattr(params, refuse_field)))
