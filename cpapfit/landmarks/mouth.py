"""How far apart the lips are: Face Mesh's inner-lip landmarks (13 upper, 14 lower), in mm.

An open mouth drops the jaw, and the template's closed mouth does not follow it: the oronasal
seal's chin part then lands millimetres from its place (see `quality`). A detection's inner-lip
pixels usually fall over the open mouth, where the depth has no skin, so they are not lifted;
instead each is taken to the depth the template's fitted lip has there.
"""

import numpy as np

from ..align.similarity import Similarity
from ..scan import Intrinsics

UPPER_INNER, LOWER_INNER = 13, 14


def lips_apart_mm(uv: np.ndarray, fit: Similarity, template_landmarks: np.ndarray, intrinsics: Intrinsics) -> float:
    """Distance (mm) between the inner lips seen at pixels uv[13] and uv[14] ((468, 2) uv), each
    taken to the camera depth of its template landmark under `fit` (template -> camera, mm)."""
    pair = [UPPER_INNER, LOWER_INNER]
    z = fit.apply(template_landmarks[pair])[:, 2]
    x = (uv[pair, 0] - intrinsics.cx) / intrinsics.fx * z
    y = (uv[pair, 1] - intrinsics.cy) / intrinsics.fy * z
    return float(np.linalg.norm([x[0] - x[1], y[0] - y[1], z[0] - z[1]]))


def lips_apart_in_points(points: np.ndarray, template_index: np.ndarray) -> float:
    """Distance (mm) between given 3-D landmarks 13 and 14 ((K, 3) points of template vertices
    `template_index`), NaN unless both are given."""
    where = {int(i): k for k, i in enumerate(template_index)}
    if UPPER_INNER not in where or LOWER_INNER not in where:
        return float("nan")
    return float(np.linalg.norm(points[where[UPPER_INNER]] - points[where[LOWER_INNER]]))
