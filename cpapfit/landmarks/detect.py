"""Landmarks by detection: MediaPipe on a capture's colour image, or on offscreen views of a mesh.

Every detection (each view, each of four image rotations, each face found) is lifted to 3-D and
scored by how well a robust similarity carries the template's landmarks onto it; the best one
that faces its camera wins. Landmarks on the far side of the head (template normal turned away
from the camera) are dropped before the final fit. On a mesh the winner is then refined: the
mesh is rendered from straight in front of the face it found, upright and filling the image, and
a detection there replaces it (an axis view of a scan in an arbitrary orientation sees the face
obliquely, and MediaPipe's landmarks on an oblique face are off by millimetres).
"""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from ..similarity import Similarity, fit_similarity
from ..errors import InputError
from ..render import Scene, scene_of
from ..scan import Intrinsics, Scan
from ..template import N_LANDMARKS, Template
from .facemesh import detect_rotations
from .lift import lift
from .mouth import lips_apart_mm
from .types import Landmarks
from .views import axis_views, face_view, render_view
from ..thresholds import BLUE_SKIN_TINT, MIN_LANDMARKS, MIN_INLIERS, TWO_FACES_MM

FACING_COS = 0.15  # a landmark whose template normal is turned further from the camera is hidden
FRONTAL_PASSES = 3  # renders from in front of the face found, each from the last one's face (3: the view settles)
# A frontal render is upright: its face is taken as MediaPipe sees it unturned, if it sees one (a
# face turned 90 deg can fit the template with less RMS and be mm off: fran as a float64 PLY);
# the image turned is tried only when it sees none.
UPRIGHT, TURNED = (0,), (1, 2, 3)
RENDER_THREADS = 2  # a mesh's axis views are rendered this many at a time (Embree and numpy release the GIL)


@dataclass(frozen=True)
class Sight:
    """An image with depth seen by a camera, and how camera points map to the scan's frame."""

    image: np.ndarray
    depth: np.ndarray
    intrinsics: Intrinsics
    to_scan: Callable[[np.ndarray], np.ndarray]
    label: str


@dataclass(frozen=True)
class Detection:
    """Landmarks found, the similarity they place the template by, how many agree with it, and the
    colour under them (`_skin_tint`; NaN where not measured)."""

    landmarks: Landmarks
    similarity: Similarity
    inliers: int
    tint: float = float("nan")


def sights(scan: Scan, scene: Scene | None) -> list[Sight]:
    """The capture's own image, or offscreen views of a mesh (none for a point cloud); `scene`: a
    mesh's (`render.scene_of`, None for a capture or a point cloud)."""
    if scan.is_capture:
        return [] if scan.image is None else [Sight(scan.image, scan.depth, scan.intrinsics, lambda p: p, "colour image")]
    if scan.is_point_cloud:
        return []
    views = axis_views(scan)
    with ThreadPoolExecutor(RENDER_THREADS) as pool:
        renders = pool.map(lambda view: render_view(scan, view, scene), views)
        return [Sight(image, depth, view.intrinsics, view.to_scan, f"render view {i}")
                for i, (view, (image, depth)) in enumerate(zip(views, renders))]


def detect_landmarks(scan: Scan, template: Template) -> Detection | None:
    """The best detection over every sight and rotation (for a mesh, refined from in front of the
    face), or None when no face is found."""
    path = "image" if scan.is_capture else "render"
    scene = None if scan.is_capture or scan.is_point_cloud else scene_of(scan.vertices, scan.faces)  # every view's
    best = _best(sights(scan, scene), template, path)
    if best is not None and path == "render":
        best = detect_from_front(scan, template, best.similarity, scene) or best
    return None if best is None else _as_found_by(best, path)


def detect_from_front(scan: Scan, template: Template, pose: Similarity, scene: Scene | None = None) -> Detection | None:
    """Detection on renders of a mesh scan from straight in front of the template placed by `pose`
    (FRONTAL_PASSES times, each from the last detection's pose), or None if none is found; `scene`:
    the mesh's (`render.scene_of`) where already built."""
    best, scene = None, scene_of(scan.vertices, scan.faces) if scene is None else scene
    for _ in range(FRONTAL_PASSES):
        view = face_view(pose.apply(template.landmarks), pose.rotation[:, 2], pose.rotation[:, 1])
        image, depth = render_view(scan, view, scene)
        seen = [Sight(image, depth, view.intrinsics, view.to_scan, "frontal render")]
        found = _best(seen, template, "render", one_face=False, turns=UPRIGHT) or _best(seen, template, "render", one_face=False, turns=TURNED)
        if found is None:
            break
        best, pose = _as_found_by(found, "render"), found.similarity
    return best


def _as_found_by(det: Detection, path: str) -> Detection:
    """The detection with its landmarks labelled as found by `path` ("image" or "render")."""
    return replace(det, landmarks=replace(det.landmarks, path=path))


def _best(seen: list[Sight], template: Template, path: str, one_face: bool = True, turns: tuple[int, ...] = (0, 1, 2, 3)) -> Detection | None:
    """The detection with the least similarity RMS over the sights and image rotations (k * 90 deg,
    k in `turns`), or None. `one_face`: refuse when the sight and rotation of that detection show two
    faces that lift onto the depth as two heads (`_refuse_two_faces`; only there: in a face turned
    upside down MediaPipe can see a second, phantom face; a frontal render frames one face only:
    skipped). InputError too where the winner's colour is blue, not skin (`_skin_tint` under
    BLUE_SKIN_TINT: the colour channels in BGR order)."""
    best, crowd = None, None
    normals = template.mesh().vertex_normals[:N_LANDMARKS]
    for sight in seen:
        for k, faces in detect_rotations(sight.image, turns):
            found = [_evaluate(sight, uv[:N_LANDMARKS], template, normals, f"{path}: {sight.label}, rotation {90 * k} deg") for uv in faces]
            found = [det for det in found if det is not None]
            for det in found:
                if best is None or det.similarity.rms_mm < best.similarity.rms_mm:
                    best, crowd = det, (found, sight)
    if one_face and crowd is not None:
        _refuse_two_faces(*crowd, template)
    if best is not None and best.tint < BLUE_SKIN_TINT:
        raise InputError(f"the face found ({best.landmarks.note.split(';')[0]}) is blue, not skin-coloured (red minus blue "
                         f"{best.tint:+.2f} of the brightness): "
                         "are the colour channels in BGR order? write the colour as RGB")
    return best


def _refuse_two_faces(found: list[Detection], sight: Sight, template: Template) -> None:
    """InputError where two of the detections `found` in one sight place the template's landmarks
    (their mean) more than TWO_FACES_MM apart: two heads. Closer, they are one head read twice (a
    noisy scan's shading seen from below gave two faces 56-92 mm apart; two patients side by side
    in one capture, 217 mm)."""
    centres = np.array([det.similarity.apply(template.landmarks).mean(axis=0) for det in found])
    if len(centres) > 1 and np.linalg.norm(centres[:, None] - centres[None], axis=2).max() > TWO_FACES_MM:
        raise InputError(f"two faces in the {sight.label}: scan one patient at a time (crop or rescan)")


def _skin_tint(image: np.ndarray, uv: np.ndarray) -> float:
    """Median (R - B) / (R + G + B) of the (H, W, 3) uint8 `image` at the (K, 2) pixels `uv`: skin
    reads +0.09 to +0.49 over the shared real scans and the synthetic skin tones; the TrueDepth frame
    with its channels swapped, -0.47."""
    h, w = image.shape[:2]
    col, row = np.clip(np.round(uv).astype(np.int64), 0, [w - 1, h - 1]).T
    rgb = image[row, col, :3].astype(float)
    return float(np.median((rgb[:, 0] - rgb[:, 2]) / np.maximum(rgb.sum(axis=1), 1.0)))


def _evaluate(sight: Sight, uv: np.ndarray, template: Template, normals: np.ndarray, note: str) -> Detection | None:
    """Lift one detection, fit the template to it, drop hidden landmarks, refit; None if implausible."""
    cam, ok = lift(uv, sight.depth, sight.intrinsics)
    if ok.sum() < MIN_LANDMARKS:
        return None
    index = np.flatnonzero(ok)
    fit = fit_similarity(template.landmarks[index], cam[index])
    facing = -(normals[index] @ fit.rotation.T)[:, 2]  # cos between template normal and the way to the camera
    if np.median(facing) < 0.3:  # the face looks away from this camera (e.g. the inside of a mesh)
        return None
    index = index[facing > FACING_COS]
    if len(index) < MIN_LANDMARKS:
        return None
    fit = fit_similarity(template.landmarks[index], cam[index])
    inliers = int((fit.weights > 0.5).sum())
    if inliers < MIN_INLIERS:
        return None
    # The similarity was fitted in camera coordinates; carry it and the points to the scan frame.
    points = sight.to_scan(cam[index])
    origin = sight.to_scan(np.zeros((1, 3)))[0]
    basis = sight.to_scan(np.eye(3)) - origin  # rows: camera axes in scan coordinates
    rotation = basis.T @ fit.rotation
    scan_fit = Similarity(fit.scale, rotation, basis.T @ fit.translation + origin, fit.weights, fit.rms_mm, fit.iterations)
    note = f"{note}; {len(index)} landmarks lifted and facing the camera, {inliers} agree with the template"
    lips = lips_apart_mm(uv, fit, template.landmarks, sight.depth, sight.intrinsics)
    landmarks = Landmarks(points, index.astype(np.int64), fit.weights, "image", note, lips_apart_mm=lips)
    return Detection(landmarks, scan_fit, inliers, _skin_tint(sight.image, uv[index]))
