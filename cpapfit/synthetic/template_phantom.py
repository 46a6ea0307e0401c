"""Synthetic subjects with ground truth: a face that is not the template, seen by a depth camera.

`make_phantom(seed)` changes the template's identity smoothly (nose, cheeks, face size, chin and
low-frequency bumps), opens the mouth or puts glasses on (`glasses.py`) if asked, poses the head in front of a virtual 640x480 depth camera at 350-700 mm,
and renders a shaded colour image and a depth image with realistic sensor effects. The truth is
the subject's surface in the template's vertex order, in the camera frame (mm), so the true
position of every template vertex (landmarks, contact regions) is known.
"""

from dataclasses import dataclass, replace

import numpy as np
import trimesh
from matplotlib.path import Path as Polygon
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from ..frozen import freeze_arrays
from .glasses import glasses_mesh
from ..render import Hits, raycast, shade
from ..scan import Intrinsics
from ..template import N_LANDMARKS, TEMPLATE_TO_CAMERA, Template, load_template



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


# Face Mesh's inner-lip contours, mouth corner to mouth corner.
UPPER_INNER_LIP = [78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308]
LOWER_INNER_LIP = [78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308]
JAW_HINGE_MM = (25.0, -85.0)  # the jaw's hinge from the upper inner lip (template frame, mm): 25 up, 85 back
CAVITY_MM = 20.0  # how far behind the lips an open mouth's inside lies
MOUTH_INSIDE = np.array([0.12, 0.04, 0.04])  # its albedo
FRAME = np.array([0.08, 0.07, 0.07])  # a glasses frame's albedo


def open_mouth(face: np.ndarray, template: Template, gap_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """((N, 3) mm vertices, (N,) bool inside the mouth) of `face` (template frame) with the jaw
    turned about its hinge so the lower inner lip moves `gap_mm` (the lips part ~3/4 of that, as
    it also moves back). The lower face turns wholly below
    the mouth, the cheeks beside it partly (blended over 25 mm); the template's skin across the
    mouth is set back CAVITY_MM into the head, the dark inside of the mouth a depth camera sees."""
    lm = template.landmarks
    inside = _inside_mouth(template)
    face = face - CAVITY_MM * inside[:, None] * [0.0, 0.0, 1.0]
    hinge = np.array([0.0, lm[13, 1] + JAW_HINGE_MM[0], lm[13, 2] + JAW_HINGE_MM[1]])
    angle = gap_mm / np.linalg.norm(lm[14] - hinge)
    turn = Rotation.from_rotvec(np.outer(angle * _jaw_weight(template), [1.0, 0.0, 0.0])).as_matrix()
    return np.einsum("nij,nj->ni", turn, face - hinge) + hinge, inside


def _jaw_weight(template: Template) -> np.ndarray:
    """(N,) how much of the jaw's turn each template vertex takes: 1 below the mouth, 0 above it,
    blended ever more gently beside and beyond the mouth corners."""
    lm, v = template.landmarks, template.vertices
    upper, lower = lm[UPPER_INNER_LIP[5:]], lm[LOWER_INNER_LIP[5:]]  # the mouth's +x half, centre to corner (symmetric)
    corner = lm[UPPER_INNER_LIP[-1], 0]
    x = np.minimum(np.abs(v[:, 0]), corner)
    line = 0.5 * (np.interp(x, upper[:, 0], upper[:, 1]) + np.interp(x, lower[:, 0], lower[:, 1]))
    width = 0.3 + 25.0 * np.clip((np.abs(v[:, 0]) - corner) / 30.0, 0.0, 1.0)
    t = np.clip((line - v[:, 1]) / width + 0.5, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _inside_mouth(template: Template) -> np.ndarray:
    """(N,) bool: template vertices over 0.3 mm inside the inner-lip contour (frontal x, y)."""
    lm, v = template.landmarks, template.vertices
    mouth = Polygon(np.vstack([lm[UPPER_INNER_LIP, :2], lm[LOWER_INNER_LIP[::-1], :2]]))
    inside = mouth.contains_points(v[:, :2], radius=0.3) & mouth.contains_points(v[:, :2], radius=-0.3)  # either winding
    return inside & (v[:, 2] > lm[13, 2] - 15.0)  # not the back of the head


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


LIP_TINT = np.array([0.85, 0.55, 0.55])  # lips: the skin's albedo times this
BROW_SHADE = 0.35  # brows: the skin's albedo times this
SCLERA = np.array([0.9, 0.9, 0.88])
IRIS = np.array([0.25, 0.16, 0.1])


def skin_tone(rng: np.random.Generator) -> np.ndarray:
    """(3,) albedo in [0, 1] of a random skin tone, from light to dark."""
    tone = rng.uniform(0.0, 1.0)
    return (1 - tone) * np.array([0.92, 0.74, 0.64]) + tone * np.array([0.45, 0.30, 0.22])


def face_regions(template: Template) -> dict[str, np.ndarray]:
    """{"lips" | "brows" | "eyes" | "iris": (N,) bool} template vertices of each coloured region
    (frontal x, y: inside the lips' and eyes' landmarks, within 4 mm of the brows' landmark edges,
    within 5.5 mm of an eye's centre)."""
    v = template.vertices
    eyes, iris = np.zeros(len(v), dtype=bool), np.zeros(len(v), dtype=bool)
    for eye in ("left_eye", "right_eye"):
        inside = _inside(template, eye)
        centre = template.landmarks[template.features[eye].ravel(), :2].mean(axis=0)
        eyes |= inside
        iris |= inside & (np.linalg.norm(v[:, :2] - centre, axis=1) < 5.5)
    brows = _near_edges(template, "left_eyebrow", 4.0) | _near_edges(template, "right_eyebrow", 4.0)
    return {"lips": _inside(template, "lips"), "brows": brows, "eyes": eyes, "iris": iris}


def skin_albedo(template: Template, rng: np.random.Generator) -> np.ndarray:
    """(N, 3) albedo in [0, 1]: a random skin tone, redder lips, dark brows, eyes with irises."""
    skin = skin_tone(rng)
    regions = face_regions(template)
    albedo = np.tile(skin, (len(template.vertices), 1))
    albedo[regions["lips"]] = skin * LIP_TINT
    albedo[regions["brows"]] = skin * BROW_SHADE
    albedo[regions["eyes"]] = SCLERA
    albedo[regions["iris"]] = IRIS
    return albedo


def _inside(template: Template, feature: str) -> np.ndarray:
    """(N,) bool: vertices inside the frontal (x, y) convex hull of a feature's landmarks."""
    pts = template.landmarks[np.unique(template.features[feature]), :2]
    hull = Polygon(pts[ConvexHull(pts).vertices])
    return hull.contains_points(template.vertices[:, :2])


def _near_edges(template: Template, feature: str, radius: float) -> np.ndarray:
    """(N,) bool: vertices within `radius` mm (frontal x, y) of a feature's landmark edges."""
    p = template.vertices[:, None, :2]
    a, b = (template.landmarks[template.features[feature][:, k], :2][None] for k in (0, 1))
    t = np.clip(np.sum((p - a) * (b - a), -1) / np.sum((b - a) ** 2, -1), 0.0, 1.0)
    return (np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=-1) < radius).any(axis=1)


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


def with_holes(ph: Phantom, region: np.ndarray, fraction: float, seed: int = 0, radius_px: tuple[float, float] = (4.0, 12.0)) -> Phantom:
    """The phantom with round depth holes (random radii in `radius_px`) centred on the region of
    template vertex indices `region`, added until at least `fraction` of the region's valid depth
    pixels are gone (a scan with holes over the mask). Colour and truth are unchanged."""
    hits = raycast(ph.surface, ph.faces, ph.intrinsics)
    in_region = np.isin(ph.faces, region).any(axis=1)
    pixels = hits.hit & in_region[np.where(hits.hit, hits.triangle, 0)] & (ph.depth_raw > 0)
    rows, cols = np.nonzero(pixels)
    rng = np.random.default_rng(seed)
    vv, uu = np.mgrid[: pixels.shape[0], : pixels.shape[1]]
    holes = np.zeros(pixels.shape, dtype=bool)
    while (holes & pixels).sum() < fraction * pixels.sum():
        k = rng.integers(len(rows))
        holes |= (uu - cols[k]) ** 2 + (vv - rows[k]) ** 2 <= rng.uniform(*radius_px) ** 2
    return replace(ph, depth_raw=np.where(holes, 0, ph.depth_raw).astype(np.uint16))


def with_colour_shift(ph: Phantom, px: int) -> Phantom:
    """The phantom with its colour image moved `px` pixels sideways (wrapping round): a capture whose
    colour is not registered to its depth. Depth and truth are unchanged."""
    return replace(ph, image=np.roll(ph.image, px, axis=1))
