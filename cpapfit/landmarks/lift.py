"""Pixel landmarks lifted to 3-D through a depth image, robustly over a small neighbourhood."""

import numpy as np

from ..rgbd import backproject_pixels
from ..scan import Intrinsics
from ..thresholds import LIFT_MIN_VALID_FRACTION, LIFT_MAX_SPREAD_MM

RADIUS_PX = 2  # 5x5 window


def lift(uv: np.ndarray, depth_mm: np.ndarray, intrinsics: Intrinsics, radius: int = RADIUS_PX):
    """(points (K, 3) mm camera frame, ok (K,) bool) for (K, 2) pixel coordinates.

    The depth of a landmark is the median of the valid depths in its (2r+1)^2 window; a landmark
    outside the image, with too few valid pixels, or on a depth edge is not ok (its point is NaN).
    """
    h, w = depth_mm.shape
    centre = np.round(uv).astype(np.int64)
    off = np.arange(-radius, radius + 1)
    du, dv = np.meshgrid(off, off)
    cols = centre[:, 0, None] + du.ravel()[None]
    rows = centre[:, 1, None] + dv.ravel()[None]
    inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
    window = np.full(cols.shape, np.nan)
    window[inside] = depth_mm[rows[inside], cols[inside]]
    ranked, count = np.sort(window, axis=1), np.isfinite(window).sum(axis=1)
    z = row_median(ranked, count)
    spread = row_percentile(ranked, count, 90) - row_percentile(ranked, count, 10)
    ok = (count / window.shape[1] >= LIFT_MIN_VALID_FRACTION) & np.isfinite(z) & (spread <= LIFT_MAX_SPREAD_MM)
    points = backproject_pixels(uv, z, intrinsics)
    points[~ok] = np.nan
    return points, ok


def row_median(ranked: np.ndarray, count: np.ndarray) -> np.ndarray:
    """(K,) median of the first count[k] values of each sorted row (NaN where none), as np.nanmedian."""
    rows, last = np.arange(len(ranked)), np.maximum(count - 1, 0)
    mid = (ranked[rows, last // 2] + ranked[rows, (last + 1) // 2]) / 2.0
    return np.where(count > 0, mid, np.nan)


def row_percentile(ranked: np.ndarray, count: np.ndarray, q: float) -> np.ndarray:
    """(K,) q-th percentile (linear) of the first count[k] values of each sorted row (NaN where none),
    with np.nanpercentile's arithmetic, so the results are the same to the bit."""
    at = (count - 1) * (q / 100.0)
    lo = np.clip(np.floor(at), 0, np.maximum(count - 1, 0)).astype(np.int64)
    hi = np.minimum(lo + 1, np.maximum(count - 1, 0))
    rows = np.arange(len(ranked))
    a, b, t = ranked[rows, lo], ranked[rows, hi], at - np.floor(at)
    diff = b - a
    out = np.where(t >= 0.5, b - diff * (1.0 - t), a + diff * t)
    return np.where(count > 0, out, np.nan)
