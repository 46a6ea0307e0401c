"""Offscreen views of a mesh scan for landmark detection: the frontal direction is not known, so
the mesh is rendered from the six axis directions (detection also tries four image rotations);
once a face is found, it is rendered again from straight in front, upright and filling the view.
"""

from dataclasses import dataclass

import numpy as np

from ..render import Scene, interpolate, look, sample_texture, shade
from ..scan import Intrinsics, Scan

SIZE = (640, 480)
SKIN = np.array([0.85, 0.68, 0.58])
VIEW_DISTANCE = 3.0  # camera distance in scan extents (mild perspective)
FILL = 0.85  # fraction of the image height the scan's extent fills
FACE_EXTENT = 1.5  # the frontal view frames this many times the landmarks' extent


@dataclass(frozen=True)
class View:
    """A virtual camera: camera-frame point p_cam = rotation @ (p_scan - centre) + [0, 0, distance]."""

    rotation: np.ndarray
    centre: np.ndarray
    distance: float
    intrinsics: Intrinsics

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        return (points - self.centre) @ self.rotation.T + [0.0, 0.0, self.distance]

    def to_scan(self, points: np.ndarray) -> np.ndarray:
        return (points - [0.0, 0.0, self.distance]) @ self.rotation + self.centre


def _look_along(direction: np.ndarray) -> np.ndarray:
    """Rotation whose third row (camera z) is `direction`, with a right-handed frame."""
    z = direction / np.linalg.norm(direction)
    helper = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z])


def axis_views(scan: Scan) -> list[View]:
    """Six views looking at the scan's centre along +-x, +-y, +-z of the scan frame."""
    centre = np.median(scan.vertices, axis=0)
    extent = float(np.ptp(scan.vertices, axis=0).max())
    return [_view(_look_along(sign * axis), centre, extent) for axis in np.eye(3) for sign in (1.0, -1.0)]


def face_view(points: np.ndarray, axis: np.ndarray, up: np.ndarray) -> View:
    """The view from straight in front of a face: looking against its unit `axis` (out of the
    face), head `up` at the top of the image, framing the (K, 3) landmark points (mm)."""
    z = -axis / np.linalg.norm(axis)
    y = -(up - (up @ z) * z)
    y /= np.linalg.norm(y)
    extent = FACE_EXTENT * float(np.ptp(points, axis=0).max())
    return _view(np.stack([np.cross(y, z), y, z]), points.mean(axis=0), extent)


def _view(rotation: np.ndarray, centre: np.ndarray, extent: float) -> View:
    """A camera VIEW_DISTANCE extents from `centre`, the extent (mm) filling FILL of the image height."""
    distance = VIEW_DISTANCE * extent
    f = FILL * SIZE[1] * distance / extent
    return View(rotation, centre, distance, Intrinsics(SIZE[0], SIZE[1], f, f, (SIZE[0] - 1) / 2, (SIZE[1] - 1) / 2))


def render_view(scan: Scan, view: View, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """(image (H, W, 3) uint8, depth (H, W) mm NaN where empty) of a mesh scan seen from a view;
    `scene`: the scan's (`render.scene_of`), built once for all its views."""
    hits, vertices, normals = look(scene, view)
    if scan.texture is not None:
        albedo, ambient = sample_texture(hits, scan.faces, scan.uv, scan.texture), 0.6
    elif scan.colors is not None:
        albedo, ambient = interpolate(hits, scan.faces, scan.colors / 255.0), 0.6
    else:
        albedo, ambient = np.tile(SKIN, (len(vertices), 1)), 0.3
    image = shade(hits, vertices, scan.faces, albedo, light=np.array([0.0, -0.3, -1.0]), ambient=ambient, normals=normals)
    return image, hits.depth
