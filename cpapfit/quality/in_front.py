"""What stands in front of the face: scan surface far out from the registered face, over its middle.

Glasses, a hand, a tube or hair between the camera and the skin: the registration passes behind
them (its pairs reject points that far off), so they are scan points lying well out along the
registered face's normals. Glasses rest their pads on the sides of the nose, where the seal goes:
on synthetic subjects wearing them the seal lay up to 0.8-2.9 mm off the skin, on the pads, mostly
unflagged.
"""

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..align.nonrigid import Registration
from ..evaluation.rim import spacing
from ..template import Template
from ..thresholds import IN_FRONT_MM

# The middle of the face: template vertices this close to the eye corners, nasion, nose tip, lips and chin.
MIDDLE_LANDMARKS = (33, 133, 263, 362, 168, 4, 0, 17, 152)
MIDDLE_RADIUS_MM = 30.0
NEIGHBOURS = 8  # a point counts if most of its nearest scan points (itself one) stand out too
REACH_MM = 35.0  # scan points farther from the registered face are not weighed (the neck and chest below the chin)


def middle_of_face(template: Template) -> np.ndarray:
    """(N,) bool: the template vertices of the middle of the face."""
    near = [np.linalg.norm(template.vertices - template.landmarks[i], axis=1) for i in MIDDLE_LANDMARKS]
    return np.min(near, axis=0) < MIDDLE_RADIUS_MM


def in_front_area_mm2(points: np.ndarray, tree: cKDTree, registration: Registration, template: Template) -> float:
    """Area (mm²) of the scan's (N, 3) `points` (mm; `tree` over them) lying IN_FRONT_MM to REACH_MM
    out from the registered face, over its middle where the registration found skin, with most of its
    NEIGHBOURS nearest points (a depth camera's noise spike stands out alone): each counts the square
    of its distance to the nearest other point (at another place), at most twice the scan's usual spacing."""
    face = registration.vertices
    normals = np.asarray(trimesh.Trimesh(face, template.faces, process=False).vertex_normals)
    dist, idx = cKDTree(face).query(points, distance_upper_bound=REACH_MM, workers=-1)
    found = np.isfinite(dist)
    idx = np.where(found, idx, 0)
    height = np.einsum("ij,ij->i", points - face[idx], normals[idx])
    out = np.flatnonzero(found & middle_of_face(template)[idx] & registration.valid[idx] & (height > IN_FRONT_MM))
    if not len(out):
        return 0.0
    apart, near = tree.query(points[out], k=min(NEIGHBOURS, len(points)))
    solid = np.median(np.where(found, height, -np.inf)[near], axis=1) > IN_FRONT_MM  # not a lone noise spike
    usual = spacing(tree)
    nearest = np.where(apart > 1e-9, apart, np.inf).min(axis=1)  # the nearest other place (a seam repeats points)
    return float(np.sum(np.minimum(nearest[solid], 2.0 * usual) ** 2))
