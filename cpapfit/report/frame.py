"""Where the report's pictures look from: cameras placed by the similarity, so every scan is
seen from the front of the face whatever its own frame; points projected into those pictures
with their visibility; positions around the seal in words."""

from dataclasses import dataclass

import numpy as np

from ..similarity import Similarity
from ..frozen import freeze_arrays
from ..landmarks.views import View
from ..template import TEMPLATE_TO_CAMERA
from ..render import Scene, look, scene_of, shade
from ..rgbd import project
from ..scan import Intrinsics

SIZE = (640, 480)
FACE_CENTRE = np.array([0.0, -10.0, 30.0])  # template frame (mm): the middle of brow-to-chin
FACE_EXTENT_MM = 210.0  # template face height the whole-face pictures show
VIEW_DISTANCE = 3.0  # camera distance in picture extents (mild perspective)
FILL = 0.9
GREY_SKIN = np.array([0.80, 0.74, 0.70])
BACKGROUND = np.array([1.0, 1.0, 1.0])
VISIBLE_TOL_MM = 2.0  # a point at most this far behind the surface the pixel sees is still drawn


@dataclass(frozen=True)
class Face:
    """The surface the pictures show: (N, 3) mm vertices (scan frame), (M, 3) faces, (N, 3) albedo in [0, 1] or None (plain skin)."""

    vertices: np.ndarray
    faces: np.ndarray
    albedo: np.ndarray | None = None

    def __post_init__(self):
        freeze_arrays(self)


def _yaw(degrees: float) -> np.ndarray:
    """Rotation about the template's up axis (y): positive turns the face towards its left."""
    a = np.radians(degrees)
    return np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])


def face_view(similarity: Similarity, centre: np.ndarray, extent_mm: float, yaw_deg: float = 0.0, size=SIZE) -> View:
    """A camera looking at the face from its front (turned by yaw_deg), centred on `centre` (scan
    frame, mm), framing extent_mm across the picture height."""
    rotation = TEMPLATE_TO_CAMERA @ _yaw(yaw_deg) @ similarity.rotation.T
    distance = VIEW_DISTANCE * extent_mm
    f = FILL * size[1] * distance / extent_mm
    return View(rotation, np.asarray(centre, dtype=float), distance, Intrinsics(size[0], size[1], f, f, (size[0] - 1) / 2, (size[1] - 1) / 2))


def whole_face_view(similarity: Similarity, yaw_deg: float = 0.0, size=SIZE) -> View:
    """Brow to chin, from the front (or turned by yaw_deg)."""
    return face_view(similarity, similarity.apply(FACE_CENTRE[None])[0], FACE_EXTENT_MM * similarity.scale, yaw_deg, size)


def seal_view(similarity: Similarity, points: np.ndarray, size=SIZE) -> View:
    """Close-up from the front on (K, 3) mm points (the rims), with a margin around them."""
    upright = (points - points.mean(axis=0)) @ similarity.rotation  # template orientation
    extent = 1.35 * max(np.ptp(upright[:, 1]), np.ptp(upright[:, 0]) * size[1] / size[0]) + 20.0
    return face_view(similarity, points.mean(axis=0), extent, 0.0, size)


@dataclass(frozen=True)
class Shot:
    """A rendered picture: its view, (H, W, 3) uint8 image and (H, W) mm depth (NaN where empty)."""

    view: View
    image: np.ndarray
    depth: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)


def shoot(face: Face, view: View, scene: Scene | None = None) -> Shot:
    """The face ray-cast and shaded from a view, on a white background; `scene`: the face's geometry
    (`render.scene_of`), when it is seen from more than one view."""
    hits, cam, normals = look(scene_of(face.vertices, face.faces) if scene is None else scene, view)
    albedo = np.tile(GREY_SKIN, (len(cam), 1)) if face.albedo is None else face.albedo
    image = shade(hits, cam, face.faces, albedo, light=np.array([-0.2, -0.3, -1.0]), ambient=0.45, background=BACKGROUND,
                  normals=normals)
    return Shot(view, image, hits.depth)


def to_pixels(shot: Shot, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((K, 2) pixel (u, v), (K,) visible) of (K, 3) mm points: in the picture and not hidden behind the
    surface it shows."""
    view, depth = shot.view, shot.depth
    cam = view.to_camera(points)
    ahead = cam[:, 2] > 1e-6
    px = project(np.where(ahead[:, None], cam, 1.0), view.intrinsics)
    h, w = depth.shape
    col, row = np.round(px[:, 0]).astype(int), np.round(px[:, 1]).astype(int)
    inside = ahead & (col >= 0) & (col < w) & (row >= 0) & (row < h)
    seen = depth[np.clip(row, 0, h - 1), np.clip(col, 0, w - 1)]
    return px, inside & (np.isnan(seen) | (cam[:, 2] <= seen + VISIBLE_TOL_MM))


def around_seal(points: np.ndarray, similarity: Similarity) -> np.ndarray:
    """(K,) degrees of each rim point around the seal seen from the front: 0 at the top (nasal
    bridge), 90 towards the patient's left, 180 at the bottom, 270 towards the patient's right."""
    upright = (points - points.mean(axis=0)) @ similarity.rotation  # template frame: x patient's left, y up
    return np.degrees(np.arctan2(upright[:, 0], upright[:, 1])) % 360.0


def place_name(degrees: float, mask: str) -> str:
    """Where around the seal an angle of `around_seal` is, in words."""
    bottom = "the upper lip" if mask == "nasal" else "the chin"
    names = ("the nasal bridge", "the patient's left cheek", bottom, "the patient's right cheek")
    return names[int(((degrees + 45.0) % 360.0) // 90.0)]
