"""Depth images as geometry: back-projection, projection and grid triangulation (camera frame, mm).

Camera frame is OpenCV's: x right, y down, z forward; pixel (u, v) has its centre at integer
coordinates, u along columns, v along rows.
"""

import numpy as np

from .scan import Intrinsics

# A triangle is dropped when its depth range exceeds what a surface at this grazing angle to the
# viewing ray could produce across one pixel diagonal: a depth jump, not a surface. Depth cameras
# see no surface beyond about 80 degrees of incidence (the synthetic sensor's returns stop there);
# steeper triangles join an edge to what lies behind it, e.g. a nostril's wing to the cheek.
MAX_SURFACE_ANGLE_DEG = 80.0


def backproject(depth_mm: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(H, W, 3) camera-frame points (mm) of an (H, W) depth image; NaN depth gives NaN points."""
    h, w = depth_mm.shape
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    return backproject_pixels(np.stack([u, v], axis=-1), depth_mm, intrinsics)


def backproject_pixels(uv: np.ndarray, z_mm: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(..., 3) camera-frame points (mm) of (..., 2) pixel coordinates (u, v) at depths (...) mm."""
    x = (uv[..., 0] - intrinsics.cx) / intrinsics.fx * z_mm
    y = (uv[..., 1] - intrinsics.cy) / intrinsics.fy * z_mm
    return np.stack([x, y, z_mm], axis=-1)


def project(points: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(N, 2) pixel coordinates (u, v) of (N, 3) camera-frame points (mm) in front of the camera."""
    z = points[:, 2]
    return np.stack(
        [intrinsics.fx * points[:, 0] / z + intrinsics.cx, intrinsics.fy * points[:, 1] / z + intrinsics.cy],
        axis=1,
    )


def color_to_depth(depth_mm: np.ndarray, intrinsics: Intrinsics, image: np.ndarray, color_intrinsics: Intrinsics,
                   depth_to_color: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8: the colour camera's (h, w, 3) uint8 `image` registered to the (H, W) depth
    image (mm, NaN invalid): each valid depth pixel's point, moved into the colour camera by the
    (4, 4) `depth_to_color` (mm), takes the colour of the pixel it lands on (nearest, as
    librealsense's align to depth); black where the depth is invalid or the point is out of view."""
    valid = np.isfinite(depth_mm)
    seen = backproject(depth_mm, intrinsics)[valid] @ depth_to_color[:3, :3].T + depth_to_color[:3, 3]
    ahead = seen[:, 2] > 0
    uv = np.full((len(seen), 2), -1, dtype=np.int64)
    uv[ahead] = np.round(project(seen[ahead], color_intrinsics)).astype(np.int64)
    inside = (uv >= 0).all(axis=1) & (uv[:, 0] < image.shape[1]) & (uv[:, 1] < image.shape[0])
    registered = np.zeros((*depth_mm.shape, 3), dtype=np.uint8)
    registered.reshape(-1, 3)[np.flatnonzero(valid)[inside]] = image[uv[inside, 1], uv[inside, 0]]
    return registered


def pixel_rays(intrinsics: Intrinsics) -> np.ndarray:
    """(H, W, 3) viewing directions through every pixel centre, with z = 1."""
    ones = np.ones((intrinsics.height, intrinsics.width))
    return backproject(ones, intrinsics)


def grid_triangles(depth_mm: np.ndarray, valid: np.ndarray, intrinsics: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate the valid pixels of a depth image.

    Returns (pixel_vertex, faces): pixel_vertex (H, W) int64 maps each valid pixel to its vertex
    index (row-major order of valid pixels) and -1 elsewhere; faces (M, 3) int64, two per 2x2
    block of valid pixels, wound so normals face the camera. Triangles spanning a depth jump
    (depth range > tan(80 deg) x one pixel diagonal's footprint) are left out.
    """
    pixel_vertex = np.full(depth_mm.shape, -1, dtype=np.int64)
    pixel_vertex[valid] = np.arange(int(valid.sum()))
    a, b = pixel_vertex[:-1, :-1], pixel_vertex[:-1, 1:]
    c, d = pixel_vertex[1:, :-1], pixel_vertex[1:, 1:]
    za, zb = depth_mm[:-1, :-1], depth_mm[:-1, 1:]
    zc, zd = depth_mm[1:, :-1], depth_mm[1:, 1:]
    f = min(intrinsics.fx, intrinsics.fy)
    slope = np.tan(np.radians(MAX_SURFACE_ANGLE_DEG)) * np.sqrt(2.0) / f
    faces = []
    for tri, zs in (((a, c, b), (za, zc, zb)), ((b, c, d), (zb, zc, zd))):
        idx = np.stack(tri, axis=-1)
        z = np.stack(zs, axis=-1)
        with np.errstate(invalid="ignore"):
            keep = (idx >= 0).all(-1) & (np.ptp(z, axis=-1) <= slope * z.min(axis=-1))
        faces.append(idx[keep])
    return pixel_vertex, np.concatenate(faces).astype(np.int64)
