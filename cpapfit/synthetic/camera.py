"""The virtual depth camera synthetic subjects are seen by, and the capture it takes.

Its intrinsics (640x480), where a head is posed in its view (`place_in_view` within a `PoseRange`),
the depth sensor's effects (`SensorModel`: noise, disparity and unit quantisation, grazing
dropout, holes), the shaded colour image with mild noise, and the capture with its truth
(`Phantom`). Camera frame: OpenCV's (x right, y down, z forward), mm.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..frozen import freeze_arrays
from ..render import Hits, shade
from ..scan import Intrinsics
from ..template import N_LANDMARKS, TEMPLATE_TO_CAMERA, Template


@dataclass(frozen=True)
class SensorModel:
    """Depth sensor effects. Noise sigma(z) = noise_mm_at_500 * (z / 500 mm)^2 (structured light /
    stereo); depth is quantised in disparity (stereo baseline, sub-pixel step) and in depth units;
    returns fade out between grazing_start_deg and grazing_stop_deg of incidence; a few random
    elliptic holes (mean count holes_mean, radius 2-10 px) are dropped."""

    noise_mm_at_500: float = 0.25
    baseline_mm: float = 50.0
    disparity_step_px: float = 1.0 / 32.0
    depth_scale: float = 10000.0  # depth units per metre: 0.1 mm
    grazing_start_deg: float = 65.0
    grazing_stop_deg: float = 80.0
    holes_mean: float = 3.0

    def sigma_mm(self, z_mm: np.ndarray) -> np.ndarray:
        """Standard deviation (mm) of the depth noise at depth z (mm)."""
        return self.noise_mm_at_500 * (np.asarray(z_mm) / 500.0) ** 2

    def disparity_step_mm(self, z_mm: np.ndarray, f_px: float) -> np.ndarray:
        """Depth step (mm) of one disparity quantum at depth z (mm) for focal length f (px)."""
        return np.asarray(z_mm) ** 2 / (f_px * self.baseline_mm) * self.disparity_step_px


KINECT_V1 = SensorModel(noise_mm_at_500=0.4, baseline_mm=75.0, disparity_step_px=1.0 / 8.0, depth_scale=1000.0)
"""A cheap structured-light camera (Kinect v1): sigma 1.6 mm and depth steps of ~2.9 mm at 1 m, depth in mm."""


@dataclass(frozen=True)
class PoseRange:
    """How the head is posed: yaw, pitch and roll drawn within +- these (degrees), and the face put
    off the image centre by this fraction of the room the image leaves (0: centred, 1: anywhere in view)."""

    yaw_deg: float = 25.0
    pitch_deg: float = 25.0
    roll_deg: float = 15.0
    off_centre: float = 1.0


ANY_POSE = PoseRange()
"""The default: any pose a depth camera can still see the face in (a hard case mix)."""
FRAMED = PoseRange(10.0, 10.0, 6.0, 0.3)
"""A capture an operator framed: the patient facing the camera, the face near the middle of the frame."""


@dataclass(frozen=True)
class Phantom:
    """A synthetic RGB-D capture and its truth.

    image: (H, W, 3) uint8 colour; depth_raw: (H, W) uint16 in units of 1/depth_scale m, 0 = invalid.
    surface: (N, 3) float64 mm, the subject's surface in the template's vertex order, camera frame.
    faces: (M, 3) int64 template triangles. identity, pose: the random parameters (for the record).
    """

    seed: int
    image: np.ndarray
    depth_raw: np.ndarray
    intrinsics: Intrinsics
    sensor: SensorModel
    surface: np.ndarray
    faces: np.ndarray
    identity: dict
    pose: dict

    def __post_init__(self):
        freeze_arrays(self)

    @property
    def landmarks(self) -> np.ndarray:
        """(468, 3) mm true landmark positions, camera frame."""
        return self.surface[:N_LANDMARKS]


def random_intrinsics(rng: np.random.Generator) -> Intrinsics:
    """640x480 intrinsics of a typical depth camera (f ~ 580-620 px, principal point near centre)."""
    f = float(rng.uniform(580.0, 620.0))
    return Intrinsics(640, 480, f, f, float(319.5 + rng.uniform(-6, 6)), float(239.5 + rng.uniform(-6, 6)))


def place_in_view(
    face: np.ndarray, template: Template, intr: Intrinsics, rng: np.random.Generator,
    yaw_deg: float | None = None, distance_mm: float | None = None, pose: PoseRange = ANY_POSE,
):
    """Pose the face within `pose` (yaw `yaw_deg` if given) at 350-700 mm (`distance_mm` if given),
    wholly inside the image.

    Returns (surface (N, 3) mm camera frame, pose dict)."""
    yaw, pitch, roll = (rng.uniform(-r, r) for r in (pose.yaw_deg, pose.pitch_deg, pose.roll_deg))
    yaw = yaw if yaw_deg is None else yaw_deg  # drawn all the same: the rest of the subject is the seed's
    head = Rotation.from_euler("yxz", [yaw, pitch, roll], degrees=True).as_matrix()
    rotation = TEMPLATE_TO_CAMERA @ head
    distance = float(rng.uniform(350.0, 700.0))
    distance = distance if distance_mm is None else float(distance_mm)
    centre = template.landmarks[[6, 4, 152, 33, 263]].mean(axis=0)
    local = (face - centre) @ rotation.T
    uv = local[:, :2] / (local[:, 2:] + distance) * [intr.fx, intr.fy]  # pixel offsets from the principal point
    margin = 8.0
    lo = -np.array([intr.cx, intr.cy]) + margin - uv.min(axis=0)
    hi = np.array([intr.width - 1 - intr.cx, intr.height - 1 - intr.cy]) - margin - uv.max(axis=0)
    a, b = np.minimum(lo, hi), np.maximum(lo, hi)
    shift_px = np.clip(pose.off_centre * rng.uniform(a, b), a, b) if (hi >= lo).all() else np.zeros(2)
    translation = np.array([*(shift_px * distance / np.array([intr.fx, intr.fy])), distance])
    placed = {
        "yaw_deg": float(yaw), "pitch_deg": float(pitch), "roll_deg": float(roll), "distance_mm": distance,
        "rotation": rotation.tolist(), "translation_mm": translation.tolist(), "template_centre_mm": centre.tolist(),
    }
    return local + translation, placed


def to_camera(points: np.ndarray, placed: dict) -> np.ndarray:
    """(K, 3) mm template-frame points in the camera frame of a `place_in_view` pose dict."""
    return (points - placed["template_centre_mm"]) @ np.array(placed["rotation"]).T + placed["translation_mm"]


def random_light(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """((3,) direction towards a random light, camera frame; (3,) background colour in [0, 1])."""
    light = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.6, 0.1), -1.0])
    return light, rng.uniform(0.35, 0.75) * np.array([1.0, 1.02, 1.06])


def camera_image(hits: Hits, vertices: np.ndarray, triangles: np.ndarray, albedo: np.ndarray, light: np.ndarray,
                 background: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(H, W, 3) uint8 colour image of a mesh ((N, 3) mm camera frame, (N, 3) albedo in [0, 1])
    shaded by `light` over `background`, with mild sensor noise."""
    image = shade(hits, vertices, triangles, albedo, light=light, background=background)
    noisy = image.astype(np.float64) + rng.normal(0.0, 2.0, image.shape)
    return np.clip(np.round(noisy), 0, 255).astype(np.uint8)


def sensor_depth(hits: Hits, intr: Intrinsics, sensor: SensorModel, rng: np.random.Generator) -> np.ndarray:
    """(H, W) uint16 raw depth: noise, disparity and unit quantisation, grazing dropout, holes."""
    z = np.where(hits.hit, hits.depth, 0.0)
    noisy = z + rng.normal(0.0, 1.0, z.shape) * sensor.sigma_mm(z)
    fb = intr.fx * sensor.baseline_mm
    with np.errstate(divide="ignore"):
        disparity = np.round(fb / noisy / sensor.disparity_step_px) * sensor.disparity_step_px
        quantised = np.where(hits.hit, fb / disparity, 0.0)
    angle = np.degrees(np.arccos(np.clip(hits.cos_incidence, 0.0, 1.0)))
    keep_p = np.clip((sensor.grazing_stop_deg - angle) / (sensor.grazing_stop_deg - sensor.grazing_start_deg), 0, 1)
    keep = hits.hit & (rng.uniform(size=z.shape) < keep_p) & ~random_holes(hits.hit, sensor.holes_mean, rng)
    raw = np.round(quantised * sensor.depth_scale / 1000.0)
    return np.where(keep, np.clip(raw, 1, 65534), 0).astype(np.uint16)


def random_holes(on_face: np.ndarray, mean_count: float, rng: np.random.Generator) -> np.ndarray:
    """(H, W) bool mask of a Poisson number of random ellipses (2-10 px radii) centred on the face."""
    holes = np.zeros(on_face.shape, dtype=bool)
    rows, cols = np.nonzero(on_face)
    vv, uu = np.mgrid[: on_face.shape[0], : on_face.shape[1]]
    for _ in range(rng.poisson(mean_count)):
        k = rng.integers(len(rows))
        ru, rv, theta = rng.uniform(2, 10), rng.uniform(2, 10), rng.uniform(0, np.pi)
        du, dv = uu - cols[k], vv - rows[k]
        a = du * np.cos(theta) + dv * np.sin(theta)
        b = -du * np.sin(theta) + dv * np.cos(theta)
        holes |= (a / ru) ** 2 + (b / rv) ** 2 <= 1.0
    return holes
