"""How far apart the lips are, in mm, read twice from a detection and the depth under it.

An open mouth drops the jaw, and the template's closed mouth does not follow it: the oronasal
seal's chin part then lands millimetres from its place (see `quality`). Two readings, the smaller
kept, as each over-reads in its own way:
- Face Mesh's inner lips (13 upper, 14 lower): over an open mouth the depth has no skin, so each
  is taken to the depth of the fitted template's lip there. MediaPipe over-reads a mouth whose lips
  a render or a colour image shows with a gap of background between them (a mesh with holes along
  the lips' crease reads 5-18 mm closed);
- the depth down the middle of the lips, from the top of the upper lip (landmark 0) to the bottom
  of the lower (17): the longest run with no skin (no depth, or over MOUTH_DEPTH_MM behind the
  lips). Holes in the scan there over-read it; teeth or tongue within MOUTH_DEPTH_MM of the lips'
  line under-read a slight opening (not tried on real faces).
"""

import numpy as np

from ..similarity import Similarity
from ..rgbd import backproject_pixels
from ..scan import Intrinsics

UPPER_INNER, LOWER_INNER = 13, 14
UPPER_OUTER, LOWER_OUTER = 0, 17
MOUTH_DEPTH_MM = 5.0  # depth this far behind the lips is the inside of the mouth
STEP_PX = 0.5


def lips_apart_mm(uv: np.ndarray, fit: Similarity, template_landmarks: np.ndarray, depth_mm: np.ndarray,
                  intrinsics: Intrinsics) -> float:
    """The smaller of the two readings (mm) for a detection: (468, 2) pixels `uv` in the image of the
    camera `intrinsics`, the similarity `fit` (template -> that camera, mm) of the (468, 3) mm
    `template_landmarks`, and the (H, W) camera depth (mm, NaN where none)."""
    lips = fit.apply(template_landmarks[[UPPER_INNER, LOWER_INNER, UPPER_OUTER, LOWER_OUTER]])
    inner = np.linalg.norm(np.subtract(*backproject_pixels(uv[[UPPER_INNER, LOWER_INNER]], lips[:2, 2], intrinsics)))
    return float(min(inner, _gap_in_depth(uv[[UPPER_OUTER, LOWER_OUTER]], lips[2:, 2], depth_mm, intrinsics)))


def _gap_in_depth(ends: np.ndarray, z: np.ndarray, depth_mm: np.ndarray, intrinsics: Intrinsics) -> float:
    """Length (mm) of the longest run without skin along the pixel segment `ends` (2, 2), whose ends
    lie at depths `z` (2,) mm: depth missing there, or over MOUTH_DEPTH_MM behind the segment."""
    count = max(2, int(np.ceil(np.linalg.norm(ends[1] - ends[0]) / STEP_PX)) + 1)
    t = np.linspace(0.0, 1.0, count)
    uv = ends[0] + t[:, None] * (ends[1] - ends[0])
    h, w = depth_mm.shape
    pixel = np.round(uv).astype(np.int64)
    inside = (pixel >= 0).all(axis=1) & (pixel < [w, h]).all(axis=1)
    col, row = np.clip(pixel, 0, [w - 1, h - 1]).T
    expected = z[0] + t * (z[1] - z[0])
    seen = depth_mm[row, col]
    open_ = inside & ~(seen <= expected + MOUTH_DEPTH_MM)  # NaN (no depth) counts as open; off the image, unknown
    if not open_.any():
        return 0.0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], open_.astype(np.int8), [0]])))
    starts, stops = edges[::2], edges[1::2] - 1
    k = int(np.argmax(stops - starts))
    a, b = backproject_pixels(uv[[starts[k], stops[k]]], expected[[starts[k], stops[k]]], intrinsics)
    return float(np.linalg.norm(a - b))


def lips_apart_in_points(points: np.ndarray, template_index: np.ndarray) -> float:
    """Distance (mm) between given 3-D landmarks 13 and 14 ((K, 3) points of template vertices
    `template_index`), NaN unless both are given."""
    where = {int(i): k for k, i in enumerate(template_index)}
    if UPPER_INNER not in where or LOWER_INNER not in where:
        return float("nan")
    return float(np.linalg.norm(points[where[UPPER_INNER]] - points[where[LOWER_INNER]]))
