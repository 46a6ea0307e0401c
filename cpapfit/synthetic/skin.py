"""A synthetic face's colours: a random skin tone, redder lips, dark brows, eyes with irises,
on the template's regions (frontal x, y of its landmarks)."""

import numpy as np
from matplotlib.path import Path as Polygon
from scipy.spatial import ConvexHull

from ..template import Template


LIP_TINT = np.array([0.85, 0.55, 0.55])  # lips: the skin's albedo times this
BROW_SHADE = 0.35  # brows: the skin's albedo times this
SCLERA = np.array([0.9, 0.9, 0.88])
IRIS = np.array([0.25, 0.16, 0.1])


def skin_tone(rng: np.random.Generator) -> np.ndarray:
    """(3,) albedo in [0, 1] of a random skin tone, from light to dark."""
    tone = rng.uniform(0.0, 1.0)
    return (1 - tone) * np.array([0.92, 0.74, 0.64]) + tone * np.array([0.45, 0.30, 0.22])


def face_regions(template: Template) -> dict[str, np.ndarray]:
    """{"lips" | "brows" | "eyes" | "iris": (N,) bool} template vertices of each coloured region
    (frontal x, y: inside the lips' and eyes' landmarks, within 4 mm of the brows' landmark edges,
    within 5.5 mm of an eye's centre)."""
    v = template.vertices
    eyes, iris = np.zeros(len(v), dtype=bool), np.zeros(len(v), dtype=bool)
    for eye in ("left_eye", "right_eye"):
        inside = _inside(template, eye)
        centre = template.landmarks[template.features[eye].ravel(), :2].mean(axis=0)
        eyes |= inside
        iris |= inside & (np.linalg.norm(v[:, :2] - centre, axis=1) < 5.5)
    brows = _near_edges(template, "left_eyebrow", 4.0) | _near_edges(template, "right_eyebrow", 4.0)
    return {"lips": _inside(template, "lips"), "brows": brows, "eyes": eyes, "iris": iris}


def skin_albedo(template: Template, rng: np.random.Generator) -> np.ndarray:
    """(N, 3) albedo in [0, 1]: a random skin tone, redder lips, dark brows, eyes with irises."""
    skin = skin_tone(rng)
    regions = face_regions(template)
    albedo = np.tile(skin, (len(template.vertices), 1))
    albedo[regions["lips"]] = skin * LIP_TINT
    albedo[regions["brows"]] = skin * BROW_SHADE
    albedo[regions["eyes"]] = SCLERA
    albedo[regions["iris"]] = IRIS
    return albedo


def _inside(template: Template, feature: str) -> np.ndarray:
    """(N,) bool: vertices inside the frontal (x, y) convex hull of a feature's landmarks."""
    pts = template.landmarks[np.unique(template.features[feature]), :2]
    hull = Polygon(pts[ConvexHull(pts).vertices])
    return hull.contains_points(template.vertices[:, :2])


def _near_edges(template: Template, feature: str, radius: float) -> np.ndarray:
    """(N,) bool: vertices within `radius` mm (frontal x, y) of a feature's landmark edges."""
    p = template.vertices[:, None, :2]
    a, b = (template.landmarks[template.features[feature][:, k], :2][None] for k in (0, 1))
    t = np.clip(np.sum((p - a) * (b - a), -1) / np.sum((b - a) ** 2, -1), 0.0, 1.0)
    return (np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=-1) < radius).any(axis=1)
