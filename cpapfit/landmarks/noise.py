"""Noise added to detected landmarks, for robustness studies: what a less accurate detector finds.

Each detected point is moved by Gaussian noise (sigma_mm per axis) and put back on the skin, the
nearest scan vertex, as a detector's errors lie along the face, not off it; the similarity is
refitted to the moved points. The same noise, seed and scan give the same landmarks.
"""

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from ..scan import Scan
from ..similarity import fit_similarity
from ..template import Template
from .detect import Detection


@dataclass(frozen=True)
class LandmarkNoise:
    """Noise on the detected landmarks: sigma_mm (mm, per axis) drawn from `seed`; 0: none."""

    sigma_mm: float = 0.0
    seed: int = 0


def on_skin(scan: Scan, points: np.ndarray, sigma_mm: float, seed: int) -> np.ndarray:
    """(K, 3) mm: the (K, 3) mm `points` moved by Gaussian noise (sigma_mm per axis, drawn from
    `seed`), each put back on the skin (the nearest scan vertex)."""
    moved = points + np.random.default_rng(seed).normal(0.0, sigma_mm, points.shape)
    return scan.vertices[cKDTree(scan.vertices).query(moved)[1]]


def with_noise(found: Detection, scan: Scan, template: Template, noise: LandmarkNoise) -> Detection:
    """`found` (a detection on `scan`) with `noise` on its landmarks and the similarity refitted to
    them, their confidence its weights, their note saying so; `found` itself when noise.sigma_mm is 0."""
    if noise.sigma_mm == 0.0:
        return found
    lm = found.landmarks
    points = on_skin(scan, lm.points, noise.sigma_mm, noise.seed)
    fit = fit_similarity(template.vertices[lm.template_index], points)
    note = f"{lm.note}; noise of {noise.sigma_mm:g} mm added (seed {noise.seed})"
    return replace(found, landmarks=replace(lm, points=points, confidence=fit.weights, note=note), similarity=fit)
