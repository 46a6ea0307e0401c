"""Affine start of the non-rigid registration: one affine map, fitted to the scan's surface, that
stretches the similarity-aligned template to the patient's proportions (a face wider, longer or
deeper than the template's), so that the elastic stage only has local shape left to find.

The fit is begun at the landmarks' own affine map (least squares, clamped like the fit) and at
the similarity; the similarity's result is taken only if it pairs clearly more of the template with
the scan (`switch_margin`). On a whole-head scan the ICP begun at the similarity ends 3 or 6 mm
from the other start's result, on the last bits of the input (fran as OBJ or GLB,
bench/RESULTS.md), while begun at the landmarks' map it lands in one place. On a half-face capture
the landmarks' map, fitted to one side, is the worse start, and the similarity's pairs 30 % more.
Without MIN_LANDMARKS landmarks, only the similarity.

A trimmed ICP: each iteration pairs the moved template's vertices with the scan (the non-rigid
stage's correspondences and rejections), keeps the closest `trim` of the pairs and solves the
12 unknowns of the map by linear least squares (point-to-plane plus a little point-to-point, as the
non-rigid stage weighs them). The map's principal stretches
are then clamped to 1 +- max_stretch: adult faces differ from the template by ~10 %, not 50 %.
"""

from dataclasses import dataclass

import numpy as np

from .correspondences import Target, closest_pairs, match

MIN_LANDMARKS = 12  # fewer could not fix the map's 12 unknowns against their own errors
IDENTITY = np.hstack([np.eye(3), np.zeros((3, 1))])
IDENTITY.setflags(write=False)


@dataclass(frozen=True)
class AffineParams:
    """iterations: ICP rounds; trim: fraction of closest pairs kept; max_stretch: bound of each
    principal stretch's departure from 1 (dimensionless); switch_margin: a later start's result
    replaces an earlier one's only if it pairs this fraction more points with the scan."""

    iterations: int = 12
    trim: float = 0.9
    max_stretch: float = 0.2
    switch_margin: float = 0.05


def fit_affine(
    points: np.ndarray, normals: np.ndarray, target: Target, weights: tuple[float, float],
    gates: tuple[float, float], params: AffineParams = AffineParams(), starts: tuple = (IDENTITY,),
) -> np.ndarray:
    """(3, 4) affine map [A | t] (mm) carrying (n, 3) points with unit normals onto the scan.

    weights: (point-to-point, point-to-plane); gates: the pair rejection (max distance mm, max
    normal angle deg); starts: (3, 4) maps to refine, in order of preference (see switch_margin).
    A start with too few pairs in its first round is its own result."""
    best, paired = _refine(points, normals, target, weights, gates, params, starts[0])
    for start in starts[1:]:
        fit, more = _refine(points, normals, target, weights, gates, params, start)
        if more > (1.0 + params.switch_margin) * paired:
            best, paired = fit, more
    return best


def starts_from(points: np.ndarray, landmarks: np.ndarray, max_stretch: float) -> tuple:
    """The starts of the fit, preferred first: given MIN_LANDMARKS (k, 3) template `points` and
    their (k, 3) scan `landmarks` (mm), their least-squares affine map, stretches clamped; then the
    identity (the similarity)."""
    if len(points) < MIN_LANDMARKS:
        return (IDENTITY,)
    centre = points.mean(axis=0)
    solution = np.linalg.lstsq(np.hstack([points - centre, np.ones((len(points), 1))]), landmarks - centre, rcond=None)[0]
    return _as_map(*_clamp(solution[:3].T, solution[3], max_stretch), centre), IDENTITY


def apply_affine(affine: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n, 3) points moved by a (3, 4) affine map."""
    return points @ affine[:, :3].T + affine[:, 3]


def _refine(points, normals, target, weights, gates, params, start) -> tuple[np.ndarray, int]:
    """The trimmed ICP begun at `start`: the (3, 4) map and how many points it pairs with the scan."""
    centre = points.mean(axis=0)
    local = points - centre
    linear, shift = start[:, :3], start[:, :3] @ centre + start[:, 3] - centre
    for _ in range(params.iterations):
        moved = local @ linear.T + shift + centre
        m = match(target, moved, _unit(normals @ np.linalg.inv(linear)), *gates)
        keep = closest_pairs(m, moved, target, params.trim)
        if len(keep) < 12:
            break
        c = target.vertices[m.index[keep]] - centre
        n = target.normals[m.index[keep]]
        linear, shift = _clamp(*_solve(local[keep], c, n, weights), params.max_stretch)
    m = match(target, local @ linear.T + shift + centre, _unit(normals @ np.linalg.inv(linear)), *gates)
    return _as_map(linear, shift, centre), int(m.valid.sum())


def _as_map(linear: np.ndarray, shift: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(3, 4) map [A | t] of x -> linear (x - centre) + shift + centre."""
    return np.hstack([linear, (shift + centre - linear @ centre)[:, None]])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)


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
