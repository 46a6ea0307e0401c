"""Morphable start of the non-rigid registration: the template's shape fitted to the scan within the
span of real faces (the ICT Face Model's identity modes, carried onto the template through its
correspondence, `cpapfit.ict.template_on_ict`), so that the elastic stage starts from a face like
the patient's and not from the template's own. Without it the membrane resists the difference
between the template's nose, cheeks and lips and the patient's as much as any other bending, and
the template slides along the skin to hide it (ICT subjects: the contact band 1.5 mm mean from its
true place, 3 mm on some).

The shape is start + sum_m c_m L D_m: D_0 the ICT neutral face less the template (the template's
own shape is c_0 = 0, the ICT mean face c_0 = 1; no prior), D_1..K the identity modes (each c ~
N(0, 1): the model's own prior, weighed against the pairs as point-to-plane residuals of 1 mm),
L the linear part of the map from the template's frame to the start (similarity and affine start).
A trimmed ICP: each round pairs the shape with the scan (the non-rigid stage's pairs and gates),
keeps the closest `trim` of them and solves the K + 1 coefficients by linear least squares.
"""

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.sparse import identity
from scipy.sparse.linalg import splu
from scipy.spatial.transform import Rotation

from ..frozen import freeze_arrays
from ..ict import load_ict, template_on_ict
from .correspondences import Target, closest_pairs, match
from .laplacian import laplacian

SMOOTHING = 2.0  # mm^2-like weight of the basis's smoothing (cotangent Laplacian, no areas)


@dataclass(frozen=True)
class MorphableParams:
    """iterations: ICP rounds at most; trim: fraction of closest pairs kept; modes: identity modes
    used (at most the shipped model's); prior_mm: the residual (mm) that one unit of a mode's prior
    weighs against, per pair (larger: the prior counts more); stride: every stride-th template
    vertex is paired (47 unknowns need no 29 000 pairs); converged: the ICP stops when no unknown
    moves more than this (coefficients, radians, mm); blend: the products (the morphable start's
    run's bending and mean pair distance, each as a share of the affine start's run's, multiplied)
    under whose first the morphable run is kept, over whose second the affine one, and between
    which the two are blended (`nonrigid.morphable_share`)."""

    iterations: int = 40
    trim: float = 0.9
    modes: int = 40
    prior_mm: float = 1.0
    stride: int = 4
    converged: float = 1e-3
    blend: tuple[float, float] = (0.85, 1.1)

    def __post_init__(self):
        if self.blend[1] < self.blend[0]:
            raise ValueError(f"blend bounds {self.blend} run backwards: (low, high), equal for a cut")


@dataclass(frozen=True)
class ShapeBasis:
    """template: (N, 3) mm template vertices; modes: (M, N, 3) mm displacements of them, template frame;
    prior: (M,) the inverse variance of each mode's coefficient (0: free)."""

    template: np.ndarray
    modes: np.ndarray
    prior: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)


def ict_basis(template: np.ndarray, faces: np.ndarray, modes: int) -> ShapeBasis:
    """The ICT shape basis (neutral less the template, then `modes` identity modes) on the template of
    (N, 3) mm vertices and (M, 3) triangles (the one `cpapfit.ict.template_on_ict` maps)."""
    model = load_ict()
    triangle, bary = template_on_ict()
    corners = model.triangles[triangle]  # (N, 3) ICT vertex of each barycentric weight

    def on_template(field: np.ndarray) -> np.ndarray:  # (..., V, 3) -> (..., N, 3)
        return np.einsum("nb,...nbc->...nc", bary, field[..., corners, :])

    fields = np.concatenate([(on_template(model.neutral) - template)[None], on_template(model.identity[:modes])])
    prior = np.concatenate([[0.0], np.ones(modes)])
    return ShapeBasis(template, smooth_fields(fields, template, faces), prior)


def smooth_fields(fields: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(M, N, 3) displacement fields of the (N, 3) mm template smoothed implicitly, (I + SMOOTHING L) X =
    fields (L its cotangent Laplacian): closest points on the ICT skin fold the template's triangles
    over in creases (582 turned over by the neutral alone, at the nostrils, lips and eyes), and a
    seal curve carried over a fold crossed itself; smoothed, none turns over by 60 degrees."""
    solve = splu((identity(len(vertices)) + SMOOTHING * laplacian(vertices, faces)).tocsc()).solve
    flat = np.transpose(fields, (1, 0, 2)).reshape(len(vertices), -1)
    return np.transpose(solve(flat).reshape(len(vertices), len(fields), 3), (1, 0, 2))


def fit_shape(
    start: np.ndarray, basis: ShapeBasis, target: Target, normals_of: Callable[[np.ndarray], np.ndarray],
    weights: tuple[float, float], gates: tuple[float, float], params: MorphableParams = MorphableParams(),
) -> np.ndarray:
    """(N, 3) mm the start (the template carried onto the scan by an affine map) with the basis's
    shape fitted to the scan, and moved rigidly with it. weights: (point-to-point, point-to-plane);
    gates: the pair rejection (max distance mm, max normal angle deg); normals_of: (N, 3) points ->
    their unit vertex normals."""
    local = np.hstack([basis.template, np.ones((len(start), 1))])
    linear = np.linalg.lstsq(local, start, rcond=None)[0][:3]  # start = template @ linear + shift
    modes = basis.modes @ linear  # (M, N, 3) in the scan's frame
    by_vertex = np.ascontiguousarray(np.transpose(modes, (1, 2, 0)))  # (N, 3, M): a vertex's rows gathered at once
    centre = start.mean(axis=0)
    coef, turn, shift = np.zeros(len(modes)), np.eye(3), np.zeros(3)
    prior = basis.prior * params.prior_mm**2
    sample = np.arange(0, len(start), params.stride)
    for _ in range(params.iterations):
        current = (start + np.tensordot(coef, modes, axes=1) - centre) @ turn.T + centre + shift
        m = match(target, current[sample], normals_of(current)[sample], *gates)
        keep = closest_pairs(m, current[sample], target, params.trim)
        if len(keep) < len(modes) + 6:
            break
        step = _solve(current[sample[keep]] - centre, turn @ by_vertex[sample[keep]], target.vertices[m.index[keep]] - centre,
                      target.normals[m.index[keep]], weights, prior, coef)
        coef = coef + step[:-6]
        small = Rotation.from_rotvec(step[-6:-3]).as_matrix()
        turn, shift = small @ turn, small @ shift + step[-3:]
        if np.abs(step).max() < params.converged:
            break
    return (start + np.tensordot(coef, modes, axes=1) - centre) @ turn.T + centre + shift


def _solve(x: np.ndarray, modes: np.ndarray, q: np.ndarray, n: np.ndarray, weights: tuple[float, float],
           prior: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """(M + 6,) the step (coefficients, then a small rotation vector and a shift, mm) minimising, over
    the P pairs of (P, 3) points `x` (about the centre) moved by the (P, 3, M) `modes` and the rigid
    step to (P, 3) scan points `q` with unit normals `n`: point-to-plane and point-to-point squares
    (weighted) plus prior_m (coef_m + step_m)^2."""
    w_pp, w_pl = weights
    p = len(x)
    rigid = np.concatenate([-_skew(x), np.broadcast_to(np.eye(3), (p, 3, 3))], axis=2)  # (P, 3, 6): w x + t
    jac = np.concatenate([modes, rigid], axis=2)  # (P, 3, M + 6)
    plane = np.einsum("pcu,pc->pu", jac, n)
    flat = jac.reshape(3 * p, -1)
    reg = np.diag(np.concatenate([prior, np.zeros(6)]))
    lhs = w_pl * plane.T @ plane + w_pp * flat.T @ flat + reg
    rhs = w_pl * plane.T @ np.einsum("pc,pc->p", q - x, n) + w_pp * flat.T @ (q - x).ravel()
    rhs[: len(prior)] -= prior * coef
    return np.linalg.solve(lhs, rhs)


def _skew(v: np.ndarray) -> np.ndarray:
    """(P, 3, 3) the cross-product matrices [v]x of (P, 3) vectors: [v]x w = v x w."""
    out = np.zeros((len(v), 3, 3))
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    return out - np.transpose(out, (0, 2, 1))
