"""Accuracy measures against ground truth (synthetic subjects), in mm."""

import numpy as np
import trimesh

from .template import Template


def mask_region(template: Template) -> np.ndarray:
    """(K,) sorted template vertex indices of both masks' contact bands."""
    return np.union1d(template.regions["nasal"].band, template.regions["oronasal"].band)


def surface_distance(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(K,) distance (mm) from each point to the closest point of a triangle mesh."""
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    _, dist, _ = trimesh.proximity.closest_point(mesh, points)
    return dist


def scan_to_template(scan_points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, region: np.ndarray) -> np.ndarray:
    """Distances (mm) from (K, 3) scan points to a registered template surface, for the points whose
    closest template triangle lies wholly in `region` (template vertex indices)."""
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    _, dist, tri = trimesh.proximity.closest_point(mesh, scan_points)
    return dist[np.isin(faces[tri], region).all(axis=1)]


def flipped_triangles(before: np.ndarray, after: np.ndarray, faces: np.ndarray, region: np.ndarray) -> int:
    """How many triangles wholly in `region` turned over (normal reversed) from `before` to `after`."""
    faces = faces[np.isin(faces, region).all(axis=1)]

    def normals(v: np.ndarray) -> np.ndarray:
        return np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])

    return int((np.einsum("ij,ij->i", normals(before), normals(after)) <= 0).sum())


def sliced_diameters(mesh, tip: np.ndarray, axis: np.ndarray, from_tip) -> np.ndarray:
    """(K,) mm: the largest least-squares circle's diameter (Kasa's algebraic fit) of `mesh`'s section
    across the unit `axis` at each distance (mm) of `from_tip` back from the point `tip`."""
    out = []
    for d in from_tip:
        flat, _ = mesh.section(plane_origin=tip - d * axis, plane_normal=axis).to_2D()
        out.append(max(_circle_diameter(np.asarray(loop)) for loop in flat.discrete))
    return np.array(out)


def _circle_diameter(points: np.ndarray) -> float:
    """Diameter (mm) of the least-squares circle through (K, 2) points."""
    a = np.column_stack([points, np.ones(len(points))])
    cx, cy, c = np.linalg.lstsq(a, (points**2).sum(axis=1), rcond=None)[0]
    return float(2.0 * np.sqrt(c + (cx**2 + cy**2) / 4.0))
