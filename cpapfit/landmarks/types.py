"""The `Landmarks` type."""

from dataclasses import dataclass

import numpy as np

from ..frozen import freeze_arrays

PATHS = ("image", "render", "fallback", "user")

WITHOUT_COLOURS = " without the scan's colours"  # said of renders of a coloured mesh drawn without its colours


@dataclass(frozen=True)
class Landmarks:
    """3-D landmarks on a scan, each tied to a template vertex.

    points: (K, 3) float64 mm in the scan's frame.
    template_index: (K,) int64 template vertex of each point (i < 468: Face Mesh landmark i).
    confidence: (K,) float64 in [0, 1]: the robust weight the landmark earned in the similarity
        fit (0 = rejected as disagreeing with the others), or 1 for user landmarks.
    path: how they were found: "image" (MediaPipe on the capture's colour image), "render"
        (MediaPipe on an offscreen render of the mesh), "fallback" (no face detected, or none
        that passed the face check: template landmarks carried by a landmark-free alignment) or "user" (a landmarks file).
    note: one line on how they were found (view, rotation, counts).
    rejected: what was found and rejected before them, in words (a detected face that failed the
        face check, or detected landmarks that lay far from the registered face); "" if nothing was.
    lips_apart_mm: how far apart the inner lips (landmarks 13, 14) are, mm (`mouth.py`); NaN
        where that is not known (the fallback, a landmarks file without both).
    """

    points: np.ndarray
    template_index: np.ndarray
    confidence: np.ndarray
    path: str
    note: str = ""
    rejected: str = ""
    lips_apart_mm: float = float("nan")

    def __post_init__(self):
        freeze_arrays(self)
