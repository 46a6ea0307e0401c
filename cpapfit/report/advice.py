"""Warnings for the person reading the report: what in the scan or the fit needs a second look,
and when to rescan. Each is one sentence that says what was measured and what to do."""

from dataclasses import dataclass

import numpy as np

from ..similarity import Similarity
from ..landmarks.types import Landmarks
from .frame import around_seal, place_name
from ..loops import longest_run, loop_lengths
from .rim import has_pressure
from ..thresholds import LOW_CONFIDENCE, LOW_CONFIDENCE_SHARE, HOLE_MM, SEAL_ON_SCAN



@dataclass(frozen=True)
class Notice:
    """level: "rescan" (a quality gate flagged the scan) or "check" (look at a picture); text: one sentence."""

    level: str
    text: str


def landmark_notices(landmarks: Landmarks) -> list[Notice]:
    """Low landmark confidence (a design placed by the face's shape alone is a quality gate's to flag:
    its landmarks are the template's, carried, with no confidence to judge)."""
    low = landmarks.confidence < LOW_CONFIDENCE
    if landmarks.path == "fallback" or low.mean() <= LOW_CONFIDENCE_SHARE:
        return []
    return [Notice("check", f"{low.sum()} of {len(low)} landmarks ({100 * low.mean():.0f} %) disagree with the others "
                            f"(confidence below {LOW_CONFIDENCE}): check that the template sits on the face.")]


def gate_notices(fit: dict) -> list[Notice]:
    """The quality gates' warnings from fit.json (`quality/gates.py`): the one place that decides "rescan advised"."""
    return [Notice("rescan", w["message"][:1].upper() + w["message"][1:] + ".") for w in fit.get("warnings", [])]


def scan_notices(curve: np.ndarray, on_scan: np.ndarray, similarity: Similarity, mask: str) -> list[Notice]:
    """Where the scan has no data under the seal curve (K, 3) mm with on_scan (K,) bool: a note to look
    at the contact picture (whether that calls for a rescan is the quality gates' to say)."""
    hole_mm, middle = longest_run(~on_scan, loop_lengths(curve))
    if hole_mm <= HOLE_MM and on_scan.mean() >= SEAL_ON_SCAN:
        return []
    where = place_name(around_seal(curve, similarity)[middle], mask) if middle >= 0 else "the seal"
    return [Notice("check", f"The scan has no data under {100 * (1 - on_scan.mean()):.0f} % of the seal (longest stretch "
                            f"{hole_mm:.0f} mm, near {where}); there the cushion follows the template, not this face: "
                            "see the contact picture.")]


def at_seal_force(fit: dict) -> bool:
    """True when fit.json's custom cushion is strapped at the least force that seals it (within 1 %)."""
    custom = fit.get("custom", {})
    seal = custom.get("seal_force_n")
    return seal is not None and custom.get("headgear_force_n", np.inf) <= 1.01 * seal


def fit_notices(rims: dict, window_kpa: tuple | None, similarity: Similarity, mask: str, least_force: bool = False) -> list[Notice]:
    """The custom cushion pressing above the window's top, or open (leaking), with where;
    `least_force` (`at_seal_force`): its headgear force is already the least that seals it, so that a lower force
    cannot ease the pressure."""
    if window_kpa is None or not has_pressure(rims):
        return []
    rim = rims["custom"]
    angle = around_seal(rim.points, similarity)
    ease = ("its headgear force is already the least that seals it, so a lower force would open the seal and its shape "
            "presses there: look at the pressure picture before making it" if least_force
            else "lower the headgear force or the interference")
    out = []
    for flag, what, advice in (
        (rim.pressure_kpa > window_kpa[1], f"presses above {window_kpa[1]:.1f} kPa", ease),
        (np.asarray(rim.open, dtype=bool), "is open (leaks)", "raise the headgear force or rescan"),
    ):
        if flag.any():
            length, middle = longest_run(flag, loop_lengths(rim.points))
            out.append(Notice("check", f"The custom cushion {what} over {loop_lengths(rim.points)[flag].sum():.0f} mm of its rim "
                                       f"(longest stretch {length:.0f} mm, near {place_name(angle[middle], mask)}): {advice}."))
    return out
