"""A point cloud made renderable, so that MediaPipe can look at it: its points facing a direction
(out of the face the landmark-free alignment found), one per THIN_MM cube (a render of 640 x 480
pixels needs no more), joined by a Delaunay triangulation of their projection across that
direction. Triangles with an edge longer than EDGE_FACTOR median edges are dropped: they bridge
holes, or join the face to what lies behind it. The points keep their colours; the surface is for
detection only, and every later stage reads the cloud itself.
"""

from dataclasses import replace

import numpy as np
from scipy.spatial import Delaunay, QhullError

from ..scan import Scan

FACING_COS = 0.1  # points whose normal turns further from the direction face away
EDGE_FACTOR = 4.0
THIN_MM = 0.7


def facing_surface(cloud: Scan, axis: np.ndarray) -> Scan:
    """A mesh `Scan` over the (N, 3) mm points of a point cloud whose normals face unit `axis`
    (vertices: the cloud's, those not facing or thinned away left unused), for rendering from
    along `axis`; the cloud itself (nothing to render, so no detection) if its facing points span
    no area."""
    facing = np.flatnonzero(cloud.normals @ axis > FACING_COS)
    facing = facing[one_per_cube(cloud.vertices[facing], THIN_MM)]
    if len(facing) < 3:
        return cloud
    helper = np.eye(3)[np.argmin(np.abs(axis))]
    across = np.stack([np.cross(axis, helper), np.cross(axis, np.cross(axis, helper))])
    try:
        triangles = facing[Delaunay(cloud.vertices[facing] @ across.T).simplices]
    except QhullError:  # all in a row, or at one place
        return cloud
    corners = cloud.vertices[triangles]
    longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    kept = triangles[longest <= EDGE_FACTOR * np.median(longest)]
    return replace(cloud, faces=kept.astype(np.int64))


def one_per_cube(points: np.ndarray, cube_mm: float) -> np.ndarray:
    """Indices (ascending) of the first of the (N, 3) points (mm) in each cube_mm cube they fall in."""
    _, first = np.unique(np.floor(points / cube_mm).astype(np.int64), axis=0, return_index=True)
    return np.sort(first)
