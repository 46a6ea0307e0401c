"""Landmark-free alignment: multi-start similarity ICP of the template's central face on the scan.

Starts: the template's forward direction (+z) turned to 26 directions around the sphere, each
with 8 rolls about it; the template's nose tip placed on the scan point most prominent along
that direction near the scan's centre (the nose-tip cue). Every start gets a few ICP steps, the
best few are refined, and the one whose template lies closest to the scan wins. The scan is
matched thinned to one point per THIN_MM cube: off a dense scan (a photogrammetry cloud) a
nearest-point query weighs thousands of nearly equidistant points, and the ICP took minutes.
"""

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ..landmarks.cloud import one_per_cube
from ..landmarks.types import Landmarks
from ..scan import Scan
from ..similarity import Similarity
from ..template import N_LANDMARKS, Template
from .icp import icp_similarity

NOSE_TIP = 4
CENTRAL_RADIUS_MM = 75.0  # template points this close to the nose tip take part
SAMPLES = (500, 1500)  # template points in the coarse round, in the refinement
ROLLS = 8
KEEP = 6  # starts refined after the coarse round
THIN_MM = 0.7  # the ICP matches one scan point per cube of this size


def directions() -> np.ndarray:
    """(26, 3) unit directions: the faces, edges and corners of a cube."""
    grid = np.array([[x, y, z] for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1) if (x, y, z) != (0, 0, 0)], float)
    return grid / np.linalg.norm(grid, axis=1, keepdims=True)


def _turn_z_to(d: np.ndarray) -> np.ndarray:
    """A rotation taking +z to unit vector d."""
    rot, _ = Rotation.align_vectors([d], [[0.0, 0.0, 1.0]])
    return rot.as_matrix()


def central_points(template: Template, n: int) -> np.ndarray:
    """(n, 3) template points of the central face (deterministic subsample)."""
    v = template.vertices
    near = np.flatnonzero(np.linalg.norm(v - v[NOSE_TIP], axis=1) < CENTRAL_RADIUS_MM)
    return v[near[np.linspace(0, len(near) - 1, n).astype(np.int64)]]


def starts(scan: Scan, template: Template) -> list[Similarity]:
    """Initial similarities: every direction and roll, nose tip on the most prominent central point."""
    pts = scan.vertices
    centre = np.median(pts, axis=0)
    radius = 0.5 * float(np.ptp(pts, axis=0).max())
    central = pts[np.linalg.norm(pts - centre, axis=1) < radius]
    out = []
    for d in directions():
        tip = central[np.argmax(central @ d)]
        base = _turn_z_to(d)
        for k in range(ROLLS):
            roll = Rotation.from_rotvec(d * (2 * np.pi * k / ROLLS)).as_matrix()
            rotation = roll @ base
            out.append(Similarity(1.0, rotation, tip - rotation @ template.vertices[NOSE_TIP]))
    return out


def thinned(points: np.ndarray, cube_mm: float) -> np.ndarray:
    """The (N, 3) points (mm) thinned to the first of each cube_mm cube they fall in, in their order."""
    return points[one_per_cube(points, cube_mm)]


def fallback_alignment(scan: Scan, template: Template) -> tuple[Landmarks, Similarity]:
    """The best multi-start ICP alignment, with the template's landmarks carried onto the scan."""
    few, many = (central_points(template, n) for n in SAMPLES)
    tree = cKDTree(thinned(scan.vertices, THIN_MM))
    coarse = sorted((icp_similarity(few, tree, s, iterations=4) for s in starts(scan, template)), key=lambda f: f.rms_mm)
    fit = min((icp_similarity(many, tree, s, iterations=30) for s in coarse[:KEEP]), key=lambda f: f.rms_mm)
    points = fit.apply(template.landmarks)
    note = f"fallback: multi-start ICP, {len(many)} template points, mean gap {fit.rms_mm:.2f} mm"
    index = np.arange(N_LANDMARKS, dtype=np.int64)
    return Landmarks(points, index, np.zeros(N_LANDMARKS), "fallback", note), fit
