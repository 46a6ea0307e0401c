"""The mask's contact region carried onto the patient: the closed seal curve and its band.

On the template, the region's centre curve (an edge path) is resampled evenly, smoothed, and
stored as barycentric points on template triangles. Through the registration (same triangles,
warped vertices) they land on the patient's face; each is then moved to the closest point of
the scan itself where the scan has data within PROJECT_MM along the skin normal (at most
TANGENT_MM sideways: near a hole the closest point is on the hole's rim, and the seal must not
be dragged there), so the cushion touches the real face rather than the template's approximation of it.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import trimesh
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from .frozen import freeze_arrays
from .template import Template, load_template

SAMPLES = 128  # points around the seal
SMOOTH_SAMPLES = 2.0  # Gaussian smoothing of the edge path, in samples
PROJECT_MM = 3.0  # farther from the scan than this: no scan data there, keep the registered point
TANGENT_MM = 1.0  # a closest scan point farther sideways than this is a hole's rim: keep the registered point


@dataclass(frozen=True)
class Contact:
    """The seal on the patient (mm, scan frame).

    curve: (K, 3) closed seal curve, ordered around the loop (last joins first).
    normals: (K, 3) unit skin normals at the curve points (out of the face).
    on_scan: (K,) bool: the point was moved onto the scan (False: no scan data near it).
    band: (B, 3) the contact band's template vertices on the patient (registered positions).
    """

    mask: str
    curve: np.ndarray
    normals: np.ndarray
    on_scan: np.ndarray
    band: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)


def closed_resample(points: np.ndarray, n: int, values: np.ndarray | None = None) -> np.ndarray:
    """n stations evenly spaced by arc length along a closed polyline (K, 3): the (n, 3) points
    there, or, given `values` (K, ...) carried by the points, those values interpolated there."""
    loop = np.vstack([points, points[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(loop, axis=0), axis=1))])
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    data = loop if values is None else np.concatenate([values, values[:1]]).reshape(len(loop), -1)
    out = np.stack([np.interp(t, s, column) for column in data.T], axis=1)
    return out.reshape((n,) + (loop.shape[1:] if values is None else np.shape(values)[1:]))


@lru_cache(maxsize=4)
def template_curve(mask: str) -> tuple[np.ndarray, np.ndarray]:
    """(triangles (K,), barycentric (K, 3)) of the smoothed seal curve on the template."""
    template = load_template()
    pts = closed_resample(template.vertices[template.regions[mask].curve], SAMPLES)
    pts = gaussian_filter1d(pts, SMOOTH_SAMPLES, axis=0, mode="wrap")
    mesh = template.mesh()
    closest, _, tri = trimesh.proximity.closest_point(mesh, pts)
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[tri], closest)
    return tri, bary


def transfer_contact(template: Template, warped: np.ndarray, surface: trimesh.Trimesh | trimesh.PointCloud, mask: str) -> Contact:
    """The seal curve and band of `mask` on the patient, from the warped template (n, 3) mm, moved
    onto the scan's surface (`scan_surface`) where it is near."""
    tri, bary = template_curve(mask)
    corners = warped[template.faces[tri]]  # (K, 3, 3)
    carried = np.einsum("kj,kjc->kc", bary, corners)
    normals = np.einsum("kj,kjc->kc", bary, trimesh.Trimesh(warped, template.faces, process=False).vertex_normals[template.faces[tri]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    curve, on_scan = onto_scan(carried, normals, surface)
    return Contact(mask, curve, normals, on_scan, warped[template.regions[mask].band])


def onto_scan(points: np.ndarray, normals: np.ndarray, surface: trimesh.Trimesh | trimesh.PointCloud) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of the scan's surface (`scan_surface`; its vertices, for a point cloud) within
    PROJECT_MM of the (K, 3) points and within TANGENT_MM of their (K, 3) unit normals' lines."""
    if isinstance(surface, trimesh.PointCloud):
        dist, idx = cKDTree(surface.vertices).query(points)
        closest = surface.vertices[idx]
    else:
        closest, dist, _ = trimesh.proximity.closest_point(surface, points)
    offset = closest - points
    sideways = np.linalg.norm(offset - np.einsum("ij,ij->i", offset, normals)[:, None] * normals, axis=1)
    near = (dist <= PROJECT_MM) & (sideways <= TANGENT_MM)
    return np.where(near[:, None], closest, points), near
