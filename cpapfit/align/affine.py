"""Affine start of the non-rigid registration: one affine map, fitted to the scan's surface, that
stretches the similarity-aligned template to the patient's proportions (a face wider, longer or
deeper than the template's), so that the elastic stage only has local shape left to find.

A trimmed ICP: each iteration pairs the moved template's vertices with the scan (the non-rigid
stage's correspondences and rejections), keeps the closest `trim` of the pairs and solves the
12 unknowns of the map by linear least squares (point-to-plane plus a little point-to-point, as the
non-rigid stage weighs them). The map's principal stretches
are then clamped to 1 +- max_stretch: adult faces differ from the template by ~10 %, not 50 %.
"""

from dataclasses import dataclass

import numpy as np

from .correspondences import Target, match


@dataclass(frozen=True)
class AffineParams:
    """iterations: ICP rounds; trim: fraction of closest pairs kept; max_stretch: bound of each
    principal stretch's departure from 1 (dimensionless)."""

    iterations: int = 12
    trim: float = 0.9
    max_stretch: float = 0.2


def fit_affine(
    points: np.ndarray, normals: np.ndarray, target: Target, weights: tuple[float, float],
    gates: tuple[float, float], params: AffineParams = AffineParams(),
) -> np.ndarray:
    """(3, 4) affine map [A | t] (mm) carrying (n, 3) points with unit normals onto the scan.

    weights: (point-to-point, point-to-plane); gates: the pair rejection (max distance mm, max
    normal angle deg). Returns the identity map if too few pairs are found."""
    centre = points.mean(axis=0)
    local = points - centre
    linear, shift = np.eye(3), np.zeros(3)
    for _ in range(params.iterations):
        moved = local @ linear.T + shift + centre
        turned = _unit(normals @ np.linalg.inv(linear))
        m = match(target, moved, turned, *gates)
        keep = _closest(m, moved, target, params.trim)
        if len(keep) < 12:
            break
        c = target.vertices[m.index[keep]] - centre
        n = target.normals[m.index[keep]]
        linear, shift = _clamp(*_solve(local[keep], c, n, weights), params.max_stretch)
    return np.hstack([linear, (shift + centre - linear @ centre)[:, None]])


def apply_affine(affine: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, 3) points moved by a (3, 4) affine map."""
    return points @ affine[:, :3].T + affine[:, 3]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)


def _closest(m, moved: np.ndarray, target: Target, trim: float) -> np.ndarray:
    """Indices of the valid pairs no farther apart than the `trim` quantile of their distances."""
    i = np.flatnonzero(m.valid)
    if len(i) == 0:
        return i
    dist = np.linalg.norm(target.vertices[m.index[i]] - moved[i], axis=1)
    return i[dist <= np.quantile(dist, trim)]


def _solve(p: np.ndarray, c: np.ndarray, n: np.ndarray, weights: tuple[float, float]):
    """Least-squares (A, t) for A p + t ~ c: point-to-plane rows n . (A p + t - c), point-to-point
    rows A p + t - c (unknowns row-major [A | t])."""
    w_pp, w_pl = weights
    ph = np.hstack([p, np.ones((len(p), 1))])
    rows = np.einsum("ki,kj->kij", n, ph).reshape(len(p), 12)  # n_i * ph_j at unknown (i, j)
    lhs = w_pl * rows.T @ rows + w_pp * np.kron(np.eye(3), ph.T @ ph)
    rhs = w_pl * rows.T @ np.einsum("ki,ki->k", n, c) + w_pp * (c.T @ ph).ravel()
    m = np.linalg.solve(lhs, rhs).reshape(3, 4)
    return m[:, :3], m[:, 3]


def _clamp(linear: np.ndarray, shift: np.ndarray, max_stretch: float):
    """The linear part with its singular values clamped to 1 +- max_stretch (and no reflection)."""
    u, s, vt = np.linalg.svd(linear)
    if np.linalg.det(u @ vt) < 0:
        return np.eye(3), shift
    return u @ np.diag(np.clip(s, 1.0 - max_stretch, 1.0 + max_stretch)) @ vt, shift
