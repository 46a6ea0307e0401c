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
