"""Accuracy measures against ground truth (synthetic subjects), in mm."""

import numpy as np
import trimesh


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
