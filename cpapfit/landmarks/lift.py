"""Pixel landmarks lifted to 3-D through a depth image, robustly over a small neighbourhood."""

import warnings

import numpy as np

from ..scan import Intrinsics

RADIUS_PX = 2  # 5x5 window
MIN_VALID_FRACTION = 0.4
MAX_SPREAD_MM = 6.0  # a window straddling a depth edge (spread of valid depths) is not trusted


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
    valid_frac = np.isfinite(window).mean(axis=1)
    with warnings.catch_warnings():  # all-NaN windows are expected: they are not ok
        warnings.simplefilter("ignore", RuntimeWarning)
        z = np.nanmedian(window, axis=1)
        spread = np.nanpercentile(window, 90, axis=1) - np.nanpercentile(window, 10, axis=1)
    ok = (valid_frac >= MIN_VALID_FRACTION) & np.isfinite(z) & (spread <= MAX_SPREAD_MM)
    x = (uv[:, 0] - intrinsics.cx) / intrinsics.fx * z
    y = (uv[:, 1] - intrinsics.cy) / intrinsics.fy * z
    points = np.stack([x, y, z], axis=1)
    points[~ok] = np.nan
    return points, ok

