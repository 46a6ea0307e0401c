"""Similarity alignment of template landmarks onto scan landmarks (the paper's method, made robust).

The paper: scale from pairwise landmark distances, then alternate rotation, translation and scale
until converged. Made robust to wrong landmarks: the initial scale is the median ratio of
pairwise distances, and every alternation is weighted by Tukey's biweight of the residuals
(iteratively reweighted least squares), so a landmark far off gets weight zero.
"""

from dataclasses import dataclass

import numpy as np

from .frozen import freeze_arrays

TUKEY_C = 4.685  # biweight tuning constant (95 % efficiency for Gaussian residuals)
MIN_SIGMA_MM = 1.0  # residual scale floor: landmarks within ~5 mm always count


@dataclass(frozen=True)
class Similarity:
    """x -> scale * R @ x + t (template frame to scan frame, mm).

    weights: (K,) final robust weight of each landmark in [0, 1] (0 = rejected as an outlier).
    rms_mm: weighted RMS residual of the landmarks after alignment.
    """

    scale: float
    rotation: np.ndarray
    translation: np.ndarray
    weights: np.ndarray | None = None
    rms_mm: float = 0.0
    iterations: int = 0

    def __post_init__(self):
        freeze_arrays(self)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) points mapped by the transform."""
        return self.scale * points @ self.rotation.T + self.translation


def pairwise_scale(src: np.ndarray, dst: np.ndarray) -> float:
    """Median ratio of pairwise distances dst/src (the paper's scale initialisation, robust)."""
    i, j = np.triu_indices(len(src), k=1)
    ds, dd = np.linalg.norm(src[i] - src[j], axis=1), np.linalg.norm(dst[i] - dst[j], axis=1)
    keep = ds > 1e-9
    return float(np.median(dd[keep] / ds[keep]))


def best_rotation(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Proper rotation R minimising sum w |R src - dst|^2 for centred (K, 3) point sets (Kabsch)."""
    u, _, vt = np.linalg.svd((dst * w[:, None]).T @ src)
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    return u @ np.diag([1.0, 1.0, d]) @ vt


def _weighted_step(src, dst, w, scale):
    """One alternation: rotation and translation at fixed scale, then the scale at fixed R, t."""
    mu_s, mu_d = np.average(src, axis=0, weights=w), np.average(dst, axis=0, weights=w)
    a, b = src - mu_s, dst - mu_d
    rotation = best_rotation(a, b, w)
    ra = a @ rotation.T
    scale = float(np.sum(w * np.einsum("ij,ij->i", ra, b)) / np.sum(w * np.einsum("ij,ij->i", ra, ra)))
    translation = mu_d - scale * rotation @ mu_s
    return scale, rotation, translation


def tukey_weights(residual: np.ndarray) -> np.ndarray:
    """(K,) biweight weights of residual norms, scale from the median absolute residual."""
    sigma = max(1.4826 * float(np.median(residual)), MIN_SIGMA_MM)
    u = residual / (TUKEY_C * sigma)
    return np.where(u < 1.0, (1.0 - u**2) ** 2, 0.0)


def fit_similarity(src: np.ndarray, dst: np.ndarray, robust: bool = True, max_iter: int = 100, tol: float = 1e-10) -> Similarity:
    """Similarity taking (K, 3) template landmarks `src` onto (K, 3) scan landmarks `dst` (mm), K >= 3."""
    w = np.ones(len(src))
    scale = pairwise_scale(src, dst) if robust else _ls_pairwise_scale(src, dst)
    rotation, translation = np.eye(3), np.zeros(3)
    for it in range(1, max_iter + 1):
        new = _weighted_step(src, dst, w, scale)
        change = abs(new[0] - scale) + np.abs(new[1] - rotation).max() + np.abs(new[2] - translation).max()
        scale, rotation, translation = new
        if robust:
            res = np.linalg.norm(scale * src @ rotation.T + translation - dst, axis=1)
            w = tukey_weights(res)
        if change < tol:
            break
    res = np.linalg.norm(scale * src @ rotation.T + translation - dst, axis=1)
    rms = float(np.sqrt(np.sum(w * res**2) / max(np.sum(w), 1e-12)))
    return Similarity(scale, rotation, translation, w, rms, it)


def _ls_pairwise_scale(src: np.ndarray, dst: np.ndarray) -> float:
    """The paper's least-squares scale: argmin_a sum (a d_src - d_dst)^2 over all pairs."""
    i, j = np.triu_indices(len(src), k=1)
    ds, dd = np.linalg.norm(src[i] - src[j], axis=1), np.linalg.norm(dst[i] - dst[j], axis=1)
    return float(ds @ dd / (ds @ ds))


def umeyama(src: np.ndarray, dst: np.ndarray) -> Similarity:
    """Closed-form least-squares similarity (Umeyama 1991), for comparison."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    a, b = src - mu_s, dst - mu_d
    u, s, vt = np.linalg.svd(b.T @ a / len(src))
    d = np.array([1.0, 1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
    rotation = u @ np.diag(d) @ vt
    scale = float(s @ d / (a**2).sum(axis=1).mean())
    return Similarity(scale, rotation, mu_d - scale * rotation @ mu_s)
