"""Non-rigid registration: the paper's elastic ICP of the similarity-aligned template onto the scan.

Six additions to the paper, all switchable: the template first gets an affine start (align/affine.py:
the face's proportions, so that the elastic stage finds only local shape); detected landmarks
(MediaPipe's, ~3.4 mm off: bench/RESULTS.md) pull with detected_landmark_factor = 0.1 of the paper's
landmark weight, ~(1 mm / 3.4 mm)^2, the inverse variance of their error against a landmark placed
to ~1 mm. A user's landmarks are registered with that weight first and earn the paper's weight
(a second registration) only if they lie within a median user_trust_mm of their places on that
face: landmarks placed to ~1 mm do (1.3-2.0 mm on the benches), MediaPipe's do not (2.1-3.4 mm),
and a careless file must not drag the seal along the skin where the geometry cannot pull it back.
And coarse gates: at the stiffest level pairs up to 15 mm and 60 deg apart are kept, the gates
narrowing with the stiffness (halved with it) to the paper's 5 mm and 25 deg, so that a part of
the face far from the template (a chin 6-10 mm off and tilted) is pulled in while the membrane is
stiff instead of being left out. And a mirror term (align/symmetry.py): the template, mirrored across
the scan's own plane of symmetry, lies on itself, at `symmetry` per vertex pair relaxed with the
membrane, so that the template's midline is the face's and an unseen part of the face takes the
shape of the side seen, while the skin is free to be asymmetric once the membrane is soft. And a
morphable start (align/morphable.py: the template's shape fitted within real faces' identity modes,
begun at the similarity): the elastic ICP runs from it too, and the two runs' bending from their
starts and mean distances from the scan, each the morphable run's as a share of the affine run's,
multiply to a product that weighs them (`morphable_share`): under `MorphableParams.blend`'s low
bound (0.85) the face is more like the model's faces than the template's and the morphable run is
kept, over its high bound (1.1) the affine run, and between them the two runs are blended, so
that two scans of one face reading products either side of a cut do not put its seal two runs
apart. With all six off
(`affine=None`, `detected_landmark_factor=1`, `user_trust_mm=inf`, `coarse_gates=None`,
`symmetry=0`, `morphable=None`) this is the paper's method.

Each iteration: (1) correspondences (k-d tree, or projection onto the depth grid of a capture);
(2) reject pairs > 5 mm apart, with normals > 25 deg apart (coarse gates: wider while stiff), or on the scan's boundary;
(3) solve for the displacement field D (from V0, the similarity-aligned template after the affine start) minimising

    0.1 * sum |V0 + D - c|^2 + 1 * sum (n_c . (V0 + D - c))^2 + 100 * D^T L D + 10 * sum_k |V0_k + D_k - r_k|^2
      + 1 * sum_(i, j) |reflect(V0_i + D_i) - (V0_j + D_j)|^2

(point-to-point, point-to-plane, membrane with cotangent weights L, landmarks r, mirror pairs (i, j));
(4) when the relative change of D (relative to the template's whole movement from the
similarity) falls under 1e-2 (or after level_iterations at one stiffness,
so that slow scans still reach the final stiffness), halve the membrane, landmark and mirror weights;
stop when that happens at the final stiffness (after `relaxations` halvings) or at max_iterations.

Speed: the point-to-plane term is linearised about the current vertex (its foot point on the
scan's tangent plane), and vertices without a pair are held at their current position with the
same weight, so the system matrix (w I + mu L + lambda S) is the same for x, y and z and does
not change between iterations at one stiffness: it is factorised once per stiffness level (a
handful of times, reusing the symbolic analysis) and each iteration is three back-substitutions.
The mirror term is solved in the plane's frame, where it adds one matrix across the plane and
another along it: two factorisations per level instead of one. The two starts' runs solve the same
matrices and share their factorisations; the matrices are the template's and the levels' weights,
so a thread of their own factorises the first level while the starts are made (`align/system.py`).
"""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from scipy.sparse import csr_matrix

from ..clustering import median_edge
from ..frozen import freeze_arrays
from ..landmarks.types import Landmarks
from ..nearest import NearestPoints
from ..scan import Scan
from ..thresholds import USER_TRUST_MM
from .affine import AffineParams, apply_affine, fit_affine, starts_from
from .correspondences import Target, make_target, match, oriented
from .laplacian import laplacian
from .morphable import MorphableParams, ShapeBasis, fit_shape
from .symmetry import MirrorPairs, MirrorTerm, mirror_pairs, mirror_term, plane_of_pairs, symmetry_plane
from .system import ElasticSystem, SharedFactors, Stiffness

# A registration's vertices are kept to 10^-GRID_DECIMALS mm (a micrometre; its residuals measured on
# the unrounded ones) and its morphable share to SHARE_DECIMALS decimals: the last bits of its solves
# vary with the memory alignment of the arrays OpenBLAS reads (~5e-12 mm), and the design downstream
# would carry them into its figures and bytes.
GRID_DECIMALS = 3
SHARE_DECIMALS = 6


@dataclass(frozen=True)
class NonrigidParams:
    """The paper's values are the defaults. correspondence: "auto" (grid for captures), "grid" or "kdtree";
    symmetry: the mirror term's weight per vertex pair at the stiffest level (0: none), its plane read
    off the scan points within symmetry_near_mm of the affine start; fused_reach_mm: a fused sweep,
    which covers the head from ear to ear, is registered on its triangles within this distance (mm,
    times the similarity's scale) of the similarity-placed mask region's centre (None: all of it;
    `pipeline.registered_part`)."""

    point_to_point: float = 0.1
    point_to_plane: float = 1.0
    membrane: float = 100.0
    landmark: float = 10.0
    max_distance_mm: float = 5.0
    max_normal_deg: float = 25.0
    relax_below: float = 1e-2
    relax_factor: float = 0.5
    relaxations: int = 5
    level_iterations: int = 8
    max_iterations: int = 40
    correspondence: str = "auto"
    min_landmark_confidence: float = 0.5
    detected_landmark_factor: float = 0.1
    user_trust_mm: float = USER_TRUST_MM
    affine: AffineParams | None = AffineParams()
    morphable: MorphableParams | None = MorphableParams()
    coarse_gates: tuple[float, float] | None = (15.0, 60.0)
    symmetry: float = 1.0
    symmetry_near_mm: float = 8.0
    fused_reach_mm: float | None = 90.0


@dataclass(frozen=True)
class IterationLog:
    """One iteration: the weights used, pairs kept, mean pair distance (mm), relative change of D."""

    iteration: int
    membrane: float
    landmark: float
    matched: int
    mean_residual_mm: float
    change: float


@dataclass(frozen=True)
class Registration:
    """The warped template (template vertex order, mm, scan frame).

    vertices: (n, 3), to the micrometre (GRID_DECIMALS); residual: (n,) distance (mm) to the matched
    scan point in the last iteration, point-to-plane (NaN where unmatched; measured on the unrounded
    vertices); valid: (n,) matched in the last iteration; log: per iteration;
    landmark_factor: the share of the paper's landmark weight used; landmark_spread_mm: median distance
    (mm) of the trusted landmarks to their template vertices on the face registered at the detected
    landmarks' weight (NaN without landmarks); bending: |L D|^2 (mm^2) of the displacement from its
    start, how far the face had to bend away from the start's shape (of a blend, the runs' blended);
    morphable_share: the morphable run's share of the vertices (0-1, to SHARE_DECIMALS; 0 with one
    start; `start` names the run that weighs most, "affine" or "morphable": the template's shape fitted within
    real faces'); other_run: (n, 3) the vertices of the run that weighs less (None with one start), how
    far the weighing moves the face; start_product: the morphable run's bending times mean pair
    distance over the affine run's (NaN with one start); start_blend: the products (low, high)
    between which the runs are blended (`morphable_share`; empty with one start). A trusted
    landmarks file registers both runs again at its weight and blends them by the same share.
    """

    vertices: np.ndarray
    residual: np.ndarray
    valid: np.ndarray
    log: tuple = field(default_factory=tuple)
    landmark_factor: float = 1.0
    landmark_spread_mm: float = np.nan
    bending: float = np.nan
    morphable_share: float = 0.0
    other_run: np.ndarray | None = None
    start_product: float = np.nan
    start_blend: tuple = ()

    def __post_init__(self):
        freeze_arrays(self)

    @property
    def start(self) -> str:
        """The start whose run weighs most: "morphable" from a share of a half, else "affine"."""
        return "morphable" if self.morphable_share >= 0.5 else "affine"

    def other_run_apart_mm(self, vertices: np.ndarray) -> float:
        """Mean distance (mm) between the registration and the run that weighs less in it at the (K,)
        template vertex indices `vertices` (a contact band); NaN with one start."""
        return np.nan if self.other_run is None else float(np.linalg.norm(self.vertices[vertices] - self.other_run[vertices], axis=1).mean())


def incidence(n_vertices: int, faces: np.ndarray) -> csr_matrix:
    """(n, m) sparse vertex-face incidence (1 where a face uses a vertex)."""
    rows = faces.ravel()
    cols = np.repeat(np.arange(len(faces)), 3)
    return csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_vertices, len(faces)))


def vertex_normals(vertices: np.ndarray, faces: np.ndarray, vf: csr_matrix | None = None) -> np.ndarray:
    """(n, 3) unit area-weighted vertex normals (vf: the incidence matrix, if already built)."""
    fn = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    vn = (incidence(len(vertices), faces) if vf is None else vf) @ fn
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-12)


def register(
    aligned: np.ndarray, faces: np.ndarray, scan: Scan, landmarks: Landmarks | None, params: NonrigidParams = NonrigidParams(),
    mirror: np.ndarray | None = None, basis: ShapeBasis | None = None,
) -> Registration:
    """Warp the similarity-aligned template (n, 3) mm onto the scan; a user's landmarks at the paper's
    weight if they agree with the face registered at the detected landmarks' (see above). mirror: (n,)
    each vertex's mirror pair on the template (`Template.mirror`), for the mirror term (None: none);
    basis: the template's shape basis for the morphable start (`morphable.ict_basis`; None: none)."""
    lm_index, lm_target = _landmark_targets(landmarks, params)
    factor = params.detected_landmark_factor if len(lm_index) else 0.0  # none to pull: recorded as none
    runs = _runs(aligned, faces, scan, (lm_index, lm_target), factor, params, mirror, basis)  # one target, the same landmarks
    product = _ratio(_product(runs[1][1]), _product(runs[0][1])) if len(runs) > 1 else np.nan
    first = _weighed(runs, product, faces, params)
    spread = float(np.median(np.linalg.norm(lm_target - first.vertices[lm_index], axis=1))) if len(lm_index) else np.nan
    if landmarks is not None and landmarks.path == "user" and spread <= params.user_trust_mm:
        setup = runs[0][0]
        with SharedFactors(len(runs), _stiffness(setup.lap, setup.mirror, lm_index, 1.0, params)) as factors:
            again = _elastic_runs(aligned, faces, [lambda setup=setup: setup for setup, _ in runs], (lm_index, lm_target), 1.0, params, factors)
        first = _weighed(again, product, faces, params)
    return replace(first, landmark_spread_mm=spread)


def morphable_share(product: float, blend: tuple[float, float]) -> float:
    """The morphable run's share (0-1) of the registration where its run's bending times mean pair
    distance is `product` times the affine run's: 1 under blend[0], 0 over blend[1] (or where the
    product is not a number: neither run paired), easing between them (smoothstep, continuous with
    its slope). ICT faces, not made from the template, read 0.12-0.85 and template-made ones
    0.93-1.34 (`bench/RESULTS.md` section 2); real faces' scans read 0.62-0.98, the same face either
    side of any cut from scan to scan."""
    lo, hi = blend
    if np.isnan(product):
        return 0.0
    if hi <= lo:  # a cut
        return float(product < lo)
    t = float(np.clip((hi - product) / (hi - lo), 0.0, 1.0))
    return t * t * (3.0 - 2.0 * t)


def _ratio(a: float, b: float) -> float:
    """a / b, inf (or NaN for 0 / 0) where b is 0."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(np.float64(a) / b)


def _weighed(runs: list, product: float, faces: np.ndarray, params: NonrigidParams) -> Registration:
    """The registration from the elastic runs ((set-up, `Registration`) pairs, the affine start's
    first): the one run, or the two blended by the morphable run's share (`morphable_share` of
    `product`), re-matched to the scan where both weigh."""
    if len(runs) == 1:
        return runs[0][1]
    (setup, affine), (_, morph) = runs
    share = round(morphable_share(product, params.morphable.blend), SHARE_DECIMALS)
    major, minor = (morph, affine) if share >= 0.5 else (affine, morph)
    if 0.0 < share < 1.0:
        vertices = share * morph.vertices + (1.0 - share) * affine.vertices
        major = replace(major, vertices=np.round(vertices, GRID_DECIMALS), bending=share * morph.bending + (1.0 - share) * affine.bending,
                        **_measured(vertices, faces, setup.target, setup.vf, params))
    return replace(major, morphable_share=share, other_run=minor.vertices,
                   start_product=product, start_blend=params.morphable.blend)


def _product(reg: Registration) -> float:
    """A run's bending (mm^2) times its mean pair distance (mm): the two terms `morphable_share` weighs."""
    return reg.bending * _mean_distance(reg)


def _mean_distance(reg: Registration) -> float:
    """Mean distance (mm) of a registration's kept pairs to their tangent planes."""
    return float(np.mean(reg.residual[reg.valid])) if reg.valid.any() else np.inf


def _measured(vertices: np.ndarray, faces: np.ndarray, target: Target, vf: csr_matrix, params: NonrigidParams) -> dict:
    """A registration's pairs with the scan at the paper's gates: residual (n,) mm (NaN unmatched), valid (n,)."""
    m = match(target, vertices, vertex_normals(vertices, faces, vf), params.max_distance_mm, params.max_normal_deg)
    return {"residual": np.where(m.valid, _plane_distance(vertices, m, target), np.nan), "valid": m.valid}


class _Setup(NamedTuple):
    """What the elastic ICP needs besides its landmarks: the incidence matrix, the scan as a
    target, the membrane's Laplacian, the start (n, 3) mm and the mirror term (or None)."""

    vf: csr_matrix
    target: Target
    lap: csr_matrix
    start: np.ndarray
    mirror: MirrorTerm | None


def _runs(aligned: np.ndarray, faces: np.ndarray, scan: Scan, landmarks: tuple, factor: float, params: NonrigidParams,
          mirror: np.ndarray | None, basis: ShapeBasis | None) -> list[tuple[_Setup, Registration]]:
    """The elastic ICP (its set-up and result) from the affine start and, given a shape basis, from the
    morphable one (`morphable.fit_shape`, begun at the similarity: the affine start, fitted to a face
    unlike the template's, slid 2-3 mm along ICT subjects' skin), each start's chain in a thread of
    its own; the system's first level is factorised meanwhile (`SharedFactors`)."""
    use_grid = params.correspondence == "grid" or (params.correspondence == "auto" and scan.is_capture)
    vf = incidence(len(aligned), faces)
    normals = vertex_normals(aligned, faces, vf)
    lap = laplacian(aligned, faces)
    pairs = None if mirror is None or params.symmetry == 0 else mirror_pairs(mirror)
    morphable = basis is not None and params.morphable is not None
    stiffness = _stiffness(lap, pairs, landmarks[0], factor, params)
    with SharedFactors(1 + morphable, stiffness) as factors:
        target = oriented(make_target(scan, use_grid, median_edge(aligned, faces)), aligned, normals)
        starts = [lambda: _affine_start(aligned, normals, target, landmarks, params)]
        if morphable:
            starts.append(lambda: fit_shape(aligned, basis, target, lambda v: vertex_normals(v, faces, vf),
                                            (params.point_to_point, params.point_to_plane),
                                            (params.max_distance_mm, params.max_normal_deg), params.morphable))

        def setup_of(start_of) -> _Setup:
            start = start_of()
            return _Setup(vf, target, lap, start, None if pairs is None else _mirror_term(start, target, pairs, params))

        setups = [lambda start_of=start_of: setup_of(start_of) for start_of in starts]
        return _elastic_runs(aligned, faces, setups, landmarks, factor, params, factors)


def _stiffness(lap: csr_matrix, mirror: MirrorPairs | MirrorTerm | None, lm_index: np.ndarray, factor: float,
               params: NonrigidParams) -> Stiffness:
    """The system's matrices at each level: the (n, n) membrane Laplacian `lap`, the mirror pairs'
    across and along matrices (of `mirror`; None: no mirror term), the landmarks at template indices
    `lm_index` pulled at `factor` of the paper's weight."""
    selector = np.zeros(lap.shape[0])
    selector[lm_index] = 1.0
    return Stiffness(params.point_to_point + params.point_to_plane, lap, selector, None if mirror is None else (mirror.across, mirror.along),
                     params.symmetry / params.membrane, params.membrane, params.landmark * factor, params.relax_factor)


def _elastic_runs(aligned: np.ndarray, faces: np.ndarray, setups: list, landmarks: tuple, factor: float,
                  params: NonrigidParams, factors: SharedFactors) -> list[tuple[_Setup, Registration]]:
    """The elastic ICP (its set-up and result) of each of `setups` (callables making a `_Setup`), each in a
    thread of its own, the runs solving with the `factors` made for them (CHOLMOD, the k-d tree
    queries and numpy's larger operations release the GIL)."""

    def run(number: int) -> tuple[_Setup, Registration]:
        try:
            setup = setups[number]()
            return setup, _register(aligned, faces, setup, landmarks, factor, params, (factors, number))
        finally:
            factors.finished(number)

    with ThreadPoolExecutor(max_workers=len(setups)) as pool:
        return list(pool.map(run, range(len(setups))))


def _mirror_term(start: np.ndarray, target: Target, pairs: MirrorPairs, params: NonrigidParams) -> MirrorTerm:
    """The mirror pairs' term about the scan's plane of symmetry, found from the (n, 3) start's."""
    near = np.isfinite(NearestPoints(start).query(target.vertices, params.symmetry_near_mm)[0])
    plane = symmetry_plane(target.vertices[near], target.normals[near], target.boundary[near], plane_of_pairs(start, pairs.mirror))
    return mirror_term(pairs, plane)


def _register(aligned: np.ndarray, faces: np.ndarray, setup: _Setup, landmarks: tuple, factor: float, params: NonrigidParams,
              shared: tuple[SharedFactors, int]) -> Registration:
    """The elastic ICP with (template indices, (k, 3) scan points) `landmarks` (`factor`: the share of the
    paper's weight they are pulled at, recorded; the weights are the shared system's); shared: (the
    factorisations shared with runs of the same system, this run's number)."""
    vf, target, lap, start, mirror = setup
    lm_index, lm_target = landmarks
    stiffness = shared[0].stiffness
    mu, lam = stiffness.weights(0)
    system = ElasticSystem(mirror, shared)
    disp = np.zeros_like(aligned)
    log = []
    relaxed, at_level = 0, 0
    for it in range(1, params.max_iterations + 1):
        at_level += 1
        current = start + disp
        m = match(target, current, vertex_normals(current, faces, vf), *_gates(params, mu))
        pull = _data_targets(current, m, target, params)
        rhs = stiffness.w_data * (pull - start)
        rhs[lm_index] += lam * (lm_target - start[lm_index])
        new = system.solve(rhs, start)
        change = float(np.linalg.norm(new - disp) / max(np.linalg.norm(start + new - aligned), 1e-12))
        disp = new
        res = _plane_distance(current, m, target)[m.valid]
        log.append(IterationLog(it, mu, lam, int(m.valid.sum()), float(res.mean()) if len(res) else np.nan, change))
        if change < params.relax_below or at_level == params.level_iterations:
            if relaxed == params.relaxations:
                break
            relaxed, at_level = relaxed + 1, 0
            mu, lam = stiffness.weights(relaxed)
            system.at(relaxed)
    final = start + disp
    return Registration(np.round(final, GRID_DECIMALS), log=tuple(log), landmark_factor=factor, bending=float(np.sum((lap @ disp) ** 2)),
                        **_measured(final, faces, target, vf, params))


def _gates(params: NonrigidParams, mu: float) -> tuple[float, float]:
    """The pair rejection (max distance mm, max normal angle deg) at membrane weight mu: the paper's,
    or with coarse_gates, those at the stiffest level narrowing with the stiffness to the paper's."""
    if params.coarse_gates is None:
        return params.max_distance_mm, params.max_normal_deg
    stiffness = mu / params.membrane
    return max(params.max_distance_mm, params.coarse_gates[0] * stiffness), max(params.max_normal_deg, params.coarse_gates[1] * stiffness)


def _affine_start(aligned: np.ndarray, normals: np.ndarray, target: Target, landmarks: tuple, params: NonrigidParams) -> np.ndarray:
    """(n, 3) the similarity-aligned template stretched by the affine start, begun at the trusted
    (template indices, (k, 3) scan points) `landmarks`' own map and at the similarity (unchanged if
    params.affine is None)."""
    if params.affine is None:
        return aligned
    weights = (params.point_to_point, params.point_to_plane)
    gates = (params.max_distance_mm, params.max_normal_deg)
    starts = starts_from(aligned[landmarks[0]], landmarks[1], params.affine.max_stretch)
    return apply_affine(fit_affine(aligned, normals, target, weights, gates, params.affine, starts), aligned)


def _plane_distance(points: np.ndarray, m, target: Target) -> np.ndarray:
    """(n,) |n . (p - c)| to each point's pair's tangent plane (mm); meaningless where unpaired."""
    idx = np.where(m.index >= 0, m.index, 0)
    return np.abs(np.einsum("ij,ij->i", points - target.vertices[idx], target.normals[idx]))


def _landmark_targets(landmarks: Landmarks | None, params: NonrigidParams):
    """(template indices, (k, 3) scan points) of the trusted landmarks."""
    if landmarks is None or landmarks.path == "fallback":
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3))
    keep = landmarks.confidence >= params.min_landmark_confidence
    return landmarks.template_index[keep], landmarks.points[keep]


def _data_targets(current: np.ndarray, m, target: Target, params: NonrigidParams) -> np.ndarray:
    """(n, 3) where the data terms pull each vertex: the weighted mean of its pair (point-to-point)
    and its foot point on the pair's tangent plane (point-to-plane); unpaired vertices stay."""
    pull = current.copy()
    i = np.flatnonzero(m.valid)
    c = target.vertices[m.index[i]]
    n = target.normals[m.index[i]]
    foot = current[i] - np.einsum("ij,ij->i", current[i] - c, n)[:, None] * n
    a, b = params.point_to_point, params.point_to_plane
    pull[i] = (a * c + b * foot) / (a + b)
    return pull
