"""Synthetic subjects drawn from the ICT face model: faces that are not the template deformed.

`make_ict_phantom(seed)` draws an identity (weights ~ N(0, 1) on every identity mode of the model:
the shipped 40 by default, or those of `model=load_ict(path)`, the full model), opens the jaw if asked, poses the whole head (face with its modelled nostril and lip insides, head, neck and
eyeballs; an open mouth's back closed CAVITY_MM behind the lips) in front of the virtual depth
camera (`camera.py`) and renders its colour and depth images with the same sensor model.
The truth is `template_truth` of the posed face: every template vertex where it lies on this face,
in template vertex order, camera frame (mm), so every consumer of the template phantoms reads it.
`ict_head_mesh(seed)` gives the same head as a mesh scan (mm, template frame, vertex colours),
with its modelled insides or only what a frontal scanner sees, and its truth.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from trimesh.ray.ray_pyembree import RayMeshIntersector

from ..frozen import freeze_arrays
from .camera import (
    ANY_POSE, Phantom, PoseRange, SensorModel, camera_image, place_in_view, random_intrinsics, random_light,
    sensor_depth, to_camera,
)
from .skin import BROW_SHADE, IRIS, LIP_TINT, SCLERA, face_regions, skin_tone
from .mouth import CAVITY_MM, MOUTH_INSIDE
from ..render import raycast
from ..rims import edge_uses
from ..template import load_template
from ..ict import IctModel, load_ict, random_subject, template_truth

VIEW_TILTS_DEG = (0.0, 30.0, 60.0)  # a frontal scanner's views: straight on, and 8 round at each other tilt
VIEW_SPACING_MM = 0.4  # their rays' spacing
IRIS_DEG, PUPIL_DEG = 32.0, 13.0  # an eyeball's iris and pupil: within these angles of straight ahead (+z)
PUPIL = np.array([0.04, 0.03, 0.03])
REGION_MM = 3.0  # model vertices this near the template take its lips and brows
MOUTH_RIM_MM = 35.0  # the mouth's rim: the face area's edges this near the lips' middle (the eye openings' are ~70 mm off)
MIN_PIECE = 20  # triangles: pieces of a frontal scan smaller than this (glimpses through a crease) are dropped


@dataclass(frozen=True)
class HeadMesh:
    """An ICT head as a mesh scan and its truth.

    seed: the subject's. mesh: trimesh.Trimesh, mm, template frame, vertex colours (uint8 RGBA).
    truth: (N, 3) float64 mm, every template vertex on the face, template vertex order, same frame.
    identity: the random parameters (for the record).
    """

    seed: int
    mesh: trimesh.Trimesh
    truth: np.ndarray
    identity: dict

    def __post_init__(self):
        freeze_arrays(self)


@lru_cache(maxsize=1)
def mouth_rim() -> np.ndarray:
    """(L, 2) int64 directed edges (as wound in their face triangle) of the face area's rim at the
    back of the lips' insides: where the model's mouth opens into the head."""
    model = load_ict()
    tri = model.triangles[(model.triangles < model.face_vertices).all(axis=1)]
    directed = tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    edges, count = edge_uses(tri)
    once = {tuple(e) for e in edges[count == 1]}
    rim = directed[[tuple(sorted(e)) in once for e in directed]]
    lips = model.neutral[model.landmarks[[62, 66]]].mean(axis=0)
    rim = rim[(np.linalg.norm(model.neutral[rim] - lips, axis=2) < MOUTH_RIM_MM).all(axis=1)]
    rim.flags.writeable = False
    return rim


def scene(face: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((V + 1, 3) mm vertices, (T + L, 3) triangles): the whole model mesh of (V, 3) `face`, its
    mouth closed at the back by a fan to a point CAVITY_MM behind the rim's centre (the last vertex)."""
    rim = mouth_rim()
    back = face[rim[:, 0]].mean(axis=0) - [0.0, 0.0, CAVITY_MM]
    cap = np.column_stack([rim[:, 1], rim[:, 0], np.full(len(rim), len(face))])
    return np.vstack([face, back]), np.vstack([load_ict().triangles, cap])


def view_directions() -> np.ndarray:
    """(D, 3) unit directions towards a frontal scanner's views (template frame: +z is straight on)."""
    dirs = [[0.0, 0.0, 1.0]]
    for tilt in np.radians(VIEW_TILTS_DEG[1:]):
        for azimuth in np.radians(np.arange(0.0, 360.0, 45.0)):
            dirs.append([np.sin(tilt) * np.cos(azimuth), np.sin(tilt) * np.sin(azimuth), np.cos(tilt)])
    return np.array(dirs)


def seen_triangles(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(T,) bool: the triangles of an (N, 3) mm mesh that a ray from some frontal view meets first
    (parallel rays VIEW_SPACING_MM apart across the mesh, from each of `view_directions`)."""
    intersector = RayMeshIntersector(trimesh.Trimesh(vertices, triangles, process=False))
    seen = np.zeros(len(triangles), dtype=bool)
    centre = vertices.mean(axis=0)
    for d in view_directions():
        u = np.cross(d, [0.0, 1.0, 0.0]) if abs(d[1]) < 0.9 else np.cross(d, [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(d, u)
        a, b = (vertices - centre) @ u, (vertices - centre) @ w
        aa, bb = np.meshgrid(np.arange(a.min(), a.max(), VIEW_SPACING_MM), np.arange(b.min(), b.max(), VIEW_SPACING_MM))
        start = centre + (np.ptp(vertices @ d) + 10.0) * d
        origins = start + aa.reshape(-1, 1) * u + bb.reshape(-1, 1) * w
        first = intersector.intersects_first(origins, np.tile(-d, (len(origins), 1)))
        seen[first[first >= 0]] = True
    return seen


@lru_cache(maxsize=1)
def _hidden_face() -> np.ndarray:
    """(V,) bool: face-area vertices of the neutral on no triangle a frontal view sees (the insides
    of the nostrils, of the lips and behind the eyelids)."""
    model = load_ict()
    vertices, triangles = scene(model.neutral)
    seen = seen_triangles(vertices, triangles)
    on_seen = np.zeros(len(vertices), dtype=bool)
    on_seen[triangles[seen].ravel()] = True
    return ~on_seen[: len(model.neutral)] & (np.arange(len(model.neutral)) < model.face_vertices)


@lru_cache(maxsize=1)
def _regions() -> dict[str, np.ndarray]:
    """{"lips" | "brows" | "inside" | "iris" | "pupil" | "eyes": (V,) bool} model vertices of each coloured region:
    lips and brows carried from the template (`face_regions`, nearest template vertex on the
    neutral within REGION_MM), the insides unseen from the front, the eyeballs' iris and pupil by
    their angle from straight ahead."""
    model = load_ict()
    template_regions = face_regions(load_template())
    distance, nearest = cKDTree(template_truth(model.neutral)).query(model.neutral)
    near = distance < REGION_MM
    eyes = np.arange(len(model.neutral)) >= model.head_vertices
    v = model.neutral
    centre = np.where(v[:, :1] > 0, v[eyes & (v[:, 0] > 0)].mean(axis=0), v[eyes & (v[:, 0] < 0)].mean(axis=0))  # its eyeball's
    ahead = (v - centre) @ [0.0, 0.0, 1.0] / np.maximum(np.linalg.norm(v - centre, axis=1), 1e-9)
    regions = {
        "lips": near & template_regions["lips"][nearest], "brows": near & template_regions["brows"][nearest],
        "inside": _hidden_face(), "eyes": eyes, "iris": eyes & (ahead > np.cos(np.radians(IRIS_DEG))),
        "pupil": eyes & (ahead > np.cos(np.radians(PUPIL_DEG))),
    }
    for mask in regions.values():
        mask.flags.writeable = False
    return regions


def ict_albedo(skin: np.ndarray) -> np.ndarray:
    """(V + 1, 3) albedo in [0, 1] of the `scene` vertices for a (3,) skin albedo: redder lips, dark
    brows, dark insides of the mouth and nostrils, white eyeballs with an iris and pupil."""
    r = _regions()
    albedo = np.tile(skin, (len(r["lips"]) + 1, 1))
    albedo[:-1][r["lips"]] = skin * LIP_TINT
    albedo[:-1][r["brows"]] = skin * BROW_SHADE
    albedo[:-1][r["inside"]] = MOUTH_INSIDE
    albedo[-1] = MOUTH_INSIDE
    albedo[:-1][r["eyes"]] = SCLERA
    albedo[:-1][r["iris"]] = IRIS
    albedo[:-1][r["pupil"]] = PUPIL
    return albedo


def make_ict_phantom(
    seed: int, sensor: SensorModel = SensorModel(), yaw_deg: float | None = None, distance_mm: float | None = None,
    pose: PoseRange = ANY_POSE, mouth_open_mm: float = 0.0, model: IctModel | None = None,
) -> Phantom:
    """The ICT subject of `seed` as an RGB-D capture with its truth: same seed and model, same
    arrays, bit for bit. `yaw_deg`, `distance_mm` and `pose` as for `template_phantom.make_phantom`
    (the same face whatever the pose); `mouth_open_mm` > 0 opens the jaw (the model's jawOpen) so
    that the lower inner lip moves that far (`jaw_open_weight`). `model`: the face model drawn from
    (`load_ict()` or `load_ict(path)`; the shipped one if None). The identity's first 40 weights
    are the same whatever the model, the rest of the draws (camera, pose, light) follow its mode count."""
    rng = np.random.default_rng(seed)
    template = load_template()
    face, identity = random_subject(rng, mouth_open_mm, model)
    truth = template_truth(face)
    intrinsics = random_intrinsics(rng)
    surface, placed = place_in_view(truth, template, intrinsics, rng, yaw_deg, distance_mm, pose)
    vertices, triangles = scene(face)
    seen = to_camera(vertices, placed)
    hits = raycast(seen, triangles, intrinsics)
    light, background = random_light(rng)
    image = camera_image(hits, seen, triangles, ict_albedo(skin_tone(rng)), light, background, rng)
    depth_raw = sensor_depth(hits, intrinsics, sensor, rng)
    return Phantom(seed, image, depth_raw, intrinsics, sensor, surface, template.faces, identity, placed)


def ict_head_mesh(seed: int, insides: bool = True, mouth_open_mm: float = 0.0, model: IctModel | None = None) -> HeadMesh:
    """The ICT subject of `seed` (the face of `make_ict_phantom(seed, mouth_open_mm=..., model=...)`)
    as a mesh scan, mm, template frame, vertex colours: the whole modelled head with the insides of
    its nostrils and lips (`insides`), or only the triangles a frontal scanner sees (`seen_triangles`:
    no insides, no back of the head). Same seed and model, same mesh."""
    rng = np.random.default_rng(seed)
    face, identity = random_subject(rng, mouth_open_mm, model)
    vertices, triangles = scene(face)
    colours = np.round(255.0 * ict_albedo(skin_tone(rng))).astype(np.uint8)
    if not insides:
        triangles = _without_crumbs(triangles[seen_triangles(vertices, triangles)])
        identity = {**identity, "insides": False}
    mesh = trimesh.Trimesh(vertices, triangles, vertex_colors=colours, process=False)
    mesh.remove_unreferenced_vertices()
    return HeadMesh(seed, mesh, template_truth(face), identity)


def _without_crumbs(triangles: np.ndarray) -> np.ndarray:
    """(T', 3) the (T, 3) triangles in connected pieces (sharing edges) of at least MIN_PIECE triangles."""
    adjacency = trimesh.graph.face_adjacency(triangles)
    pieces = trimesh.graph.connected_component_labels(adjacency, node_count=len(triangles))
    return triangles[np.bincount(pieces)[pieces] >= MIN_PIECE]
