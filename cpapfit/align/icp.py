"""Similarity ICP of template points onto a scan (trimmed point-to-point, bounded scale)."""

import numpy as np
from scipy.spatial import cKDTree

from ..similarity import Similarity, umeyama

TRIM = 0.8  # fraction of closest pairs kept each iteration
MAX_PAIR_MM = 20.0
SCALE_BOUNDS = (0.75, 1.35)  # adult faces relative to the template
GAP_CAP_MM = 10.0  # the score: mean distance to the scan, each capped here


def icp_similarity(src: np.ndarray, tree: cKDTree, start: Similarity, iterations: int = 20) -> Similarity:
    """Refine `start` so that (K, 3) template points `src` lie on the scan points indexed by `tree`.

    The result's rms_mm is the score: the mean distance (mm) of the moved points to the scan, each
    capped at GAP_CAP_MM (points off the scan count as the cap)."""
    fit = start
    scan = tree.data
    for it in range(iterations):
        moved = fit.apply(src)
        dist, idx = tree.query(moved, distance_upper_bound=MAX_PAIR_MM, workers=-1)  # far points: inf, quickly
        near = np.isfinite(dist)
        if near.sum() < 10:
            break
        keep = near & (dist <= np.quantile(dist[near], TRIM))
        step = umeyama(src[keep], scan[idx[keep]])
        scale = float(np.clip(step.scale, *SCALE_BOUNDS))
        fit = Similarity(scale, step.rotation, step.translation, iterations=it + 1)
    dist, _ = tree.query(fit.apply(src), distance_upper_bound=GAP_CAP_MM, workers=-1)
    gap = float(np.mean(np.minimum(dist, GAP_CAP_MM)))
    return Similarity(fit.scale, fit.rotation, fit.translation, rms_mm=gap, iterations=fit.iterations)
