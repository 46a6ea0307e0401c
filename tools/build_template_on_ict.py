"""Rebuild cpapfit/ict/data/template_on_ict.npz: every template vertex as a point of the ICT topology.

The template is registered onto the shipped ICT neutral face (the face area and the eyes, as a
scanner sees them) with cpapfit's own machinery: the similarity from landmark pairs, then the
non-rigid registration with those pairs as a user's landmarks (the paper's weight). The pairs are
the usual Multi-PIE 68 -> Face Mesh mapping's nose, eye, mouth and chin points (CANDIDATES),
screened twice: a pair whose residual is an outlier (over OUTLIER_SIGMAS robust sigmas above the
median) after the similarity fit, then on the registered face, has definitions that disagree and
is left out; what is left must be `cpapfit.ict.MULTIPIE_TO_FACEMESH`. Each registered template
vertex's closest point on the neutral's skin (the face area; within the eye openings, on the face
and eyes: the eyeball) is then kept as (ICT triangle, barycentric coordinates).

Usage (needs the project venv; no ../shared: it reads the shipped model):
    python tools/build_template_on_ict.py
"""

from pathlib import Path

import numpy as np
import trimesh
from matplotlib.path import Path as Polygon
from scipy.spatial import ConvexHull

from cpapfit.align.nonrigid import Registration, register
from cpapfit.similarity import fit_similarity
from cpapfit.ict import MULTIPIE_TO_FACEMESH, IctModel, load_ict, template_truth
from cpapfit.landmarks.types import Landmarks
from cpapfit.scan import Scan
from cpapfit.template import Template, load_template

CANDIDATES = {
    8: 152, 27: 168, 28: 197, 29: 5, 30: 4, 31: 98, 32: 97, 33: 2, 34: 326, 35: 327,
    36: 33, 39: 133, 42: 362, 45: 263, 48: 61, 51: 0, 54: 291, 57: 17, 62: 13, 66: 14,
}
OUTLIER_SIGMAS = 3.0
EYE_INSET_MM = 1.0  # template vertices this far inside an eye's contour lie on the eyeball, the rest on the skin
OUT = Path(__file__).resolve().parents[1] / "cpapfit" / "ict" / "data" / "template_on_ict.npz"


def seen_surface(model: IctModel) -> Scan:
    """The neutral's face area and eyes as a mesh scan (mm, template frame; unused vertices dropped)."""
    tri = model.triangles[model.face_and_eyes]
    used, faces = np.unique(tri, return_inverse=True)
    mesh = trimesh.Trimesh(model.neutral[used], faces.reshape(-1, 3), process=False)
    return Scan(np.array(mesh.vertices), np.array(mesh.faces), np.array(mesh.vertex_normals), source="ICT neutral face and eyes")


def outliers(residual_mm: np.ndarray) -> np.ndarray:
    """(K,) bool: residuals over OUTLIER_SIGMAS robust sigmas (1.4826 MAD) above their median."""
    median = np.median(residual_mm)
    return residual_mm > median + OUTLIER_SIGMAS * 1.4826 * np.median(np.abs(residual_mm - median))


def similarity_residuals(template: Template, model: IctModel, pairs: dict) -> np.ndarray:
    """(K,) mm residual of each pair's ICT landmark after the similarity fit of the template's onto them."""
    src, dst = template.vertices[list(pairs.values())], model.neutral[model.landmarks[list(pairs)]]
    return np.linalg.norm(fit_similarity(src, dst).apply(src) - dst, axis=1)


def registration(scan: Scan, template: Template, model: IctModel, pairs: dict) -> Registration:
    """The template registered onto the scan of the neutral with `pairs` as user landmarks."""
    index = np.array(list(pairs.values()))
    points = model.neutral[model.landmarks[list(pairs)]]
    fit = fit_similarity(template.vertices[index], points)
    landmarks = Landmarks(points, index, fit.weights, "user", "ICT neutral's Multi-PIE landmarks")
    return register(fit.apply(template.vertices), template.faces, scan, landmarks, mirror=template.mirror)


def landmark_gaps(vertices: np.ndarray, model: IctModel, pairs: dict) -> np.ndarray:
    """(K,) mm from each pair's template vertex ((N, 3) template-order `vertices`) to its ICT landmark."""
    return np.linalg.norm(vertices[list(pairs.values())] - model.neutral[model.landmarks[list(pairs)]], axis=1)


def screened(scan: Scan, template: Template, model: IctModel) -> tuple[dict, Registration]:
    """(the pairs kept, the registration with them), outliers dropped after the similarity and
    after the registration; prints each stage's residuals."""
    similarity_mm = similarity_residuals(template, model, CANDIDATES)
    _report("after the similarity fit", CANDIDATES, similarity_mm)
    pairs = {k: i for (k, i), out in zip(CANDIDATES.items(), outliers(similarity_mm)) if not out}
    reg = registration(scan, template, model, pairs)
    gaps = landmark_gaps(reg.vertices, model, pairs)
    _report("on the registered face", pairs, gaps)
    kept = {k: i for (k, i), out in zip(pairs.items(), outliers(gaps)) if not out}
    return kept, registration(scan, template, model, kept)


def _report(what: str, pairs: dict, mm: np.ndarray, starred: bool = True) -> None:
    """Print per-pair figures (mm), outliers starred if `starred`."""
    stars = outliers(mm) & starred
    print(f"{what} (mm): " + " ".join(f"{k}{'*' if out else ''}:{x:.2f}" for k, x, out in zip(pairs, mm, stars)))


def eye_openings(template: Template, inset_mm: float = EYE_INSET_MM) -> np.ndarray:
    """(N,) bool: template vertices over inset_mm inside either eye's contour (frontal x, y: the
    convex hull of its Face Mesh landmarks)."""
    inside = np.zeros(len(template.vertices), dtype=bool)
    for eye in ("left_eye", "right_eye"):
        pts = template.landmarks[np.unique(template.features[eye]), :2]
        hull = Polygon(pts[ConvexHull(pts).vertices])
        inside |= hull.contains_points(template.vertices[:, :2], radius=inset_mm) & hull.contains_points(template.vertices[:, :2], radius=-inset_mm)
    return inside


def closest_on(model: IctModel, chosen: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((K,) int64 ICT triangle, (K, 3) barycentric coordinates) of the closest point of the neutral's
    triangles `chosen` (indices) to each of (K, 3) mm points."""
    mesh = trimesh.Trimesh(model.neutral, model.triangles[chosen], process=False)
    closest, _, tri = trimesh.proximity.closest_point(mesh, points)
    bary = np.clip(trimesh.triangles.points_to_barycentric(mesh.triangles[tri], closest), 0.0, 1.0)
    return chosen[tri], bary / bary.sum(axis=1, keepdims=True)


def correspondence(vertices: np.ndarray, template: Template, model: IctModel) -> tuple[np.ndarray, np.ndarray]:
    """((N,) int32 ICT triangle, (N, 3) float32 barycentric coordinates) of each of (N, 3) mm
    registered template vertices: its closest point on the neutral's skin (the face area), or, in
    the eye openings, on the face and eyes (the eyeball seen there)."""
    t = model.triangles
    skin = np.flatnonzero((t < model.face_vertices).all(axis=1))
    triangle, bary = closest_on(model, skin, vertices)
    eyes = eye_openings(template)
    triangle[eyes], bary[eyes] = closest_on(model, model.face_and_eyes, vertices[eyes])
    return triangle.astype(np.int32), bary.astype(np.float32)


def main() -> None:
    model, template = load_ict(), load_template()
    scan = seen_surface(model)
    kept, reg = screened(scan, template, model)
    assert kept == MULTIPIE_TO_FACEMESH, f"the screened pairs {kept} are not cpapfit.ict.MULTIPIE_TO_FACEMESH"
    res = reg.residual[reg.valid]
    print(f"registration: {reg.valid.mean():.1%} of the template matched, residual median {np.median(res):.3f} mm, "
          f"p95 {np.percentile(res, 95):.3f} mm, max {res.max():.3f} mm; landmark spread {reg.landmark_spread_mm:.2f} mm")
    triangle, bary = correspondence(reg.vertices, template, model)
    np.savez_compressed(OUT, triangle=triangle, bary=bary)
    truth = template_truth(model.neutral)
    moved = np.linalg.norm(truth - reg.vertices, axis=1)
    print(f"wrote {OUT} ({OUT.stat().st_size / 1e6:.2f} MB); registered template to its closest "
          f"points: median {np.median(moved):.3f} mm, p95 {np.percentile(moved, 95):.3f} mm, max {moved.max():.2f} mm")
    _report("template landmarks on the neutral", kept, landmark_gaps(truth, model, kept), starred=False)


if __name__ == "__main__":
    main()
