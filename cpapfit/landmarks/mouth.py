"""How far apart the lips are, in mm, read from a detection and the depth under it.

An open mouth drops the jaw, and the template's closed mouth does not follow it: the oronasal
seal's chin part then lands millimetres from its place (see `quality`). Two readings, each wrong
in its own way:
- Face Mesh's inner lips (13 upper, 14 lower): over an open mouth the depth has no skin, so each
  is taken to the depth of the fitted template's lip there. MediaPipe over-reads a mouth whose lips
  a render or a colour image shows with a gap of background between them (a mesh with holes along
  the lips' crease reads 5-18 mm closed), and under-reads a mouth showing its teeth (it takes them
  for lips: 4.5-11.7 mm on ICT faces whose inner lips are 14 mm apart);
- the depth down the middle of the lips, from the top of the upper lip (landmark 0) to the bottom
  of the lower (17): the longest run with no skin, i.e. no depth or depth over MOUTH_DEPTH_MM behind
  the lips' line. That line is taken twice, through the fitted template's lips and through the
  scan's own depth at the two ends (the fitted lips' where an end is off the image, has no depth,
  or lies over MOUTH_BACK_MM behind them), and a point is behind only if behind both (a face seen
  from the side misplaces either). A run mostly of surface seen up to MOUTH_BACK_MM behind is the
  inside of the mouth (teeth, tongue); a run mostly without depth, or seen further back, may be a
  hole in the scan, which over-reads.

The reading is the smaller of the two, or the longest run mostly inside the mouth if longer: holes
over-read either reading, but only an open mouth shows surface 5-60 mm behind the lips (a hole
shows none, or what lies further back).
"""

import numpy as np

from ..similarity import Similarity
from ..rgbd import backproject_pixels
from ..scan import Intrinsics

UPPER_INNER, LOWER_INNER = 13, 14
UPPER_OUTER, LOWER_OUTER = 0, 17
MOUTH_DEPTH_MM = 5.0  # depth this far behind the lips is the inside of the mouth
MOUTH_BACK_MM = 60.0  # ... and no further: surface beyond is seen through a hole (the back of a head), or background
STEP_PX = 0.5


def lips_apart_mm(uv: np.ndarray, fit: Similarity, template_landmarks: np.ndarray, depth_mm: np.ndarray,
                  intrinsics: Intrinsics) -> float:
    """The reading (mm) for a detection: (468, 2) pixels `uv` in the image of the camera
    `intrinsics`, the similarity `fit` (template -> that camera, mm) of the (468, 3) mm
    `template_landmarks`, and the (H, W) camera depth (mm, NaN where none)."""
    lips = fit.apply(template_landmarks[[UPPER_INNER, LOWER_INNER, UPPER_OUTER, LOWER_OUTER]])
    inner = np.linalg.norm(np.subtract(*backproject_pixels(uv[[UPPER_INNER, LOWER_INNER]], lips[:2, 2], intrinsics)))
    anywhere, inside_mouth = _gaps_in_depth(uv[[UPPER_OUTER, LOWER_OUTER]], lips[2:, 2], depth_mm, intrinsics)
    return float(max(min(inner, anywhere), inside_mouth))


def _gaps_in_depth(ends: np.ndarray, z: np.ndarray, depth_mm: np.ndarray, intrinsics: Intrinsics) -> tuple[float, float]:
    """Lengths (mm) of the longest run without skin along the pixel segment `ends` (2, 2), whose ends
    lie at depths `z` (2,) mm, and of the longest such run mostly of surface seen inside a mouth
    (teeth, tongue: MOUTH_DEPTH_MM to MOUTH_BACK_MM behind). Without skin is depth missing, or over
    MOUTH_DEPTH_MM behind both the line between `z` and the line between the depths seen at the ends
    (`_end_depth`). A run's length is from its first sample to its last, at the depth of `z`'s line."""
    count = max(2, int(np.ceil(np.linalg.norm(ends[1] - ends[0]) / STEP_PX)) + 1)
    t = np.linspace(0.0, 1.0, count)
    uv = ends[0] + t[:, None] * (ends[1] - ends[0])
    h, w = depth_mm.shape
    pixel = np.round(uv).astype(np.int64)
    on_image = (pixel >= 0).all(axis=1) & (pixel < [w, h]).all(axis=1)
    col, row = np.clip(pixel, 0, [w - 1, h - 1]).T
    expected = z[0] + t * (z[1] - z[0])
    at_ends = [_end_depth(depth_mm, row[k], col[k], z[i]) if on_image[k] else z[i] for i, k in enumerate((0, -1))]
    behind = depth_mm[row, col] - np.maximum(expected, at_ends[0] + t * (at_ends[1] - at_ends[0]))
    open_ = on_image & ~(behind <= MOUTH_DEPTH_MM)  # NaN (no depth) counts as open; off the image, unknown
    mouth = open_ & (behind <= MOUTH_BACK_MM)  # seen, and no further back than a mouth goes (not through a hole)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], open_.astype(np.int8), [0]])))
    runs = list(zip(edges[::2], edges[1::2] - 1))
    length = [float(np.linalg.norm(np.subtract(*backproject_pixels(uv[[a, b]], expected[[a, b]], intrinsics)))) for a, b in runs]
    in_mouth = [2 * mouth[a:b + 1].sum() >= b + 1 - a for a, b in runs]
    return max(length, default=0.0), max((n for n, m in zip(length, in_mouth) if m), default=0.0)


def _end_depth(depth_mm: np.ndarray, row: int, col: int, z: float, half: int = 2) -> float:
    """Depth (mm) at an end of the lips' segment: the median of the (2 half + 1)^2 pixels about
    (row, col), or the fitted lips' depth `z` where none has depth or it lies over MOUTH_BACK_MM
    behind `z` (the background beside a profile, not the lips)."""
    patch = depth_mm[max(row - half, 0):row + half + 1, max(col - half, 0):col + half + 1]
    seen = np.nanmedian(patch) if np.isfinite(patch).any() else np.nan
    return float(seen) if seen - z <= MOUTH_BACK_MM else float(z)


def lips_apart_in_points(points: np.ndarray, template_index: np.ndarray) -> float:
    """Distance (mm) between given 3-D landmarks 13 and 14 ((K, 3) points of template vertices
    `template_index`), NaN unless both are given."""
    where = {int(i): k for k, i in enumerate(template_index)}
    if UPPER_INNER not in where or LOWER_INNER not in where:
        return float("nan")
    return float(np.linalg.norm(points[where[UPPER_INNER]] - points[where[LOWER_INNER]]))
