"""Template-made synthetic subjects: a face that is not the template, seen by a depth camera.

`make_phantom(seed)` changes the template's identity smoothly (nose, cheeks, face size, chin and
low-frequency bumps), opens the mouth (`mouth.py`) or puts glasses on (`glasses.py`) if asked,
colours it (`skin.py`), poses the head in front of the virtual 640x480 depth camera at 350-700 mm
and renders a shaded colour image and a depth image with realistic sensor effects (`camera.py`).
The truth is the subject's surface in the template's vertex order, in the camera frame (mm), so
the true position of every template vertex (landmarks, contact regions) is known.
"""

import numpy as np
import trimesh

from ..render import Hits, raycast
from ..template import Template, load_template
from .camera import (
    ANY_POSE, Phantom, PoseRange, SensorModel, camera_image, place_in_view, random_intrinsics, random_light, sensor_depth, to_camera,
)
from .glasses import FRAME, glasses_mesh
from .mouth import MOUTH_INSIDE, open_mouth
from .skin import skin_albedo


def make_phantom(
    seed: int, sensor: SensorModel = SensorModel(), yaw_deg: float | None = None, distance_mm: float | None = None,
    pose: PoseRange = ANY_POSE, mouth_open_mm: float = 0.0, glasses: bool = False,
) -> Phantom:
    """The synthetic subject of `seed`: same seed, same arrays, bit for bit. `yaw_deg` turns the
    head by that yaw, `distance_mm` sets it that far from the camera, instead of the random ones;
    `pose` bounds the random pose (everything else as for the seed: the same face whatever the pose);
    `mouth_open_mm` > 0 drops the jaw: the lower inner lip moves that far (`open_mouth`); `glasses`
    puts a frame on the face (`glasses.glasses_mesh`), seen by the camera, not part of the truth."""
    rng = np.random.default_rng(seed)
    template = load_template()
    identity = random_identity(rng)
    face, mouth = apply_identity(template, identity), np.zeros(len(template.vertices), dtype=bool)
    if mouth_open_mm > 0:
        face, mouth = open_mouth(face, template, mouth_open_mm)
        identity = {**identity, "mouth_open_mm": float(mouth_open_mm)}
    worn = glasses_mesh(face, template) if glasses else trimesh.Trimesh()
    if glasses:
        identity = {**identity, "glasses": True}
    intrinsics = random_intrinsics(rng)
    surface, placed = place_in_view(face, template, intrinsics, rng, yaw_deg, distance_mm, pose)
    seen = np.vstack([surface, to_camera(np.asarray(worn.vertices).reshape(-1, 3), placed)])
    triangles = np.vstack([template.faces, np.asarray(worn.faces, dtype=np.int64).reshape(-1, 3) + len(surface)])
    hits = raycast(seen, triangles, intrinsics)
    image = colour_image(hits, seen, triangles, template, rng, mouth)
    depth_raw = sensor_depth(hits, intrinsics, sensor, rng)
    return Phantom(seed, image, depth_raw, intrinsics, sensor, surface, template.faces, identity, placed)


def random_identity(rng: np.random.Generator) -> dict:
    """Random identity parameters (dimensionless scales, mm offsets) within adult variation."""
    u = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731
    return {
        "scale": u(0.9, 1.1), "face_width": u(0.92, 1.08), "face_height": u(0.92, 1.08),
        "nose_length": u(0.85, 1.15), "nose_width": u(0.85, 1.2), "nose_projection_mm": u(-3.0, 4.0),
        "cheek_fullness_mm": u(-2.5, 3.5), "chin_forward_mm": u(-4.0, 4.0), "chin_down_mm": u(-4.0, 4.0),
        "bumps": [[u(-60, 60), u(-80, 40), u(-1.5, 1.5), u(12, 25)] for _ in range(6)],
    }


def _gauss(points: np.ndarray, centre: np.ndarray, sigma: float) -> np.ndarray:
    """(N,) Gaussian weights of (N, 3) points around a centre (all mm)."""
    return np.exp(-np.sum((points - centre) ** 2, axis=1) / (2.0 * sigma**2))


def apply_identity(template: Template, p: dict) -> np.ndarray:
    """(N, 3) mm vertices of the template changed by identity parameters `p` (template frame)."""
    v = template.vertices.copy()
    lm = template.landmarks
    root, tip = lm[6], lm[4]
    w_nose = _gauss(v, (root + tip) / 2.0, 16.0)
    v[:, 1] += (p["nose_length"] - 1.0) * (v[:, 1] - root[1]) * w_nose
    v[:, 0] += (p["nose_width"] - 1.0) * (v[:, 0] - tip[0]) * _gauss(v, tip + [0, -5, -8], 12.0)
    v[:, 2] += p["nose_projection_mm"] * _gauss(v, tip, 11.0)
    normals = template.mesh().vertex_normals
    for side in (50, 280):
        v += p["cheek_fullness_mm"] * _gauss(template.vertices, lm[side], 16.0)[:, None] * normals
    w_chin = _gauss(v, lm[152] + [0, 10, 0], 22.0)
    v[:, 2] += p["chin_forward_mm"] * w_chin
    v[:, 1] -= p["chin_down_mm"] * w_chin
    for x, y, amp, sigma in p["bumps"]:
        v += amp * _gauss(template.vertices, np.array([x, y, lm[4, 2] - 30.0]), sigma)[:, None] * normals
    centre = lm[168]
    scale = p["scale"] * np.array([p["face_width"], p["face_height"], 1.0])
    return (v - centre) * scale + centre


def colour_image(hits: Hits, seen: np.ndarray, triangles: np.ndarray, template: Template, rng: np.random.Generator,
                 mouth: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 shaded colour image with a random light and mild sensor noise of the face
    (its first N vertices of `seen`, the template's) and anything worn on it (the rest, in FRAME's
    colour); the (N,) bool `mouth` vertices are the dark inside of an open mouth."""
    light, background = random_light(rng)
    albedo = skin_albedo(template, rng)
    albedo[mouth] = MOUTH_INSIDE
    albedo = np.vstack([albedo, np.tile(FRAME, (len(seen) - len(albedo), 1))])
    return camera_image(hits, seen, triangles, albedo, light, background, rng)
