"""Initial alignment of the template on a scan: landmarks (user, detected, or none) and a similarity."""

from dataclasses import replace
from typing import Iterator

import numpy as np

from ..errors import InputError
from ..scan import Scan, robust_extent
from ..template import Template, central_face, mask_region
from ..landmarks.detect import Detection, detect_from_front, detect_landmarks
from ..landmarks.cloud import facing_surface
from ..landmarks.noise import LandmarkNoise, with_noise
from .fallback import fallback_alignment
from ..landmarks.types import WITHOUT_COLOURS, Landmarks
from .check import FaceCheck, check_face, require_face, scale_question
from ..similarity import Similarity, fit_similarity
from ..thresholds import FRONT_SIZE, DISAGREE_MM, SCALE_RANGE


# A capture's second look, only to agree or not with its image's low-nosed face (`_agreed`): MediaPipe
# on a render of its depth, without colours, from in front of that face.
SECOND_LOOK = "a render of the depth" + WITHOUT_COLOURS


def initial_alignment(scan: Scan, template: Template, user: Landmarks | None = None,
                      noise: LandmarkNoise = LandmarkNoise()) -> tuple[Landmarks, Similarity, FaceCheck]:
    """Landmarks, the similarity carrying the template onto the scan, and the face check.

    User landmarks override detection. Otherwise the first of these that lies on a face wins: the
    detection (with `noise` on its landmarks, `with_noise`: none by default); for a mesh with
    colours, the detection on its renders without them (a texture misplaced on the surface, or colours that are not skin, mislead the detector: when the coloured
    renders show no face, or one that fails the face check); a detection on a
    render from in front of the face the landmark-free fallback finds, if of that face's size
    (meshes, and point clouds through a surface over their points: a capture's own image is the
    best view there is); the fallback itself. The winner's `rejected` names those that failed the face
    check (a capture's colour image not registered to its depth puts the detected face off the
    scanned one). A candidate that fails the check only by a low nose (`FaceCheck.low_nose`) wins
    when a later one, or a capture's SECOND_LOOK, places the mask region within DISAGREE_MM of it
    (`_agreed`). If none lies on a face the scan is refused (InputError)."""
    central = central_face(template)
    if user is not None:
        fit = fit_similarity(template.vertices[user.template_index], user.points)
        candidates = [("user", Detection(replace(user, confidence=fit.weights, path="user", note="user landmarks file"), fit, len(user.points)))]
    else:
        candidates = _candidates(scan, template, noise)
    found, check, failed, agreed = _first_face(scan, template, candidates, central)
    if not agreed:
        across = np.nan if check.is_face or scan.is_capture else robust_extent(scan.vertices)  # a capture's depth has the room in it
        require_face(check, f"landmarks by {found.landmarks.path}", scale_question(scan), across)
    if found.landmarks.path == "fallback":
        require_agreement(template, found.similarity, failed, _size_doubt(scan, failed))
    rejected = f"the face found by {' and '.join(dict.fromkeys(label for label, _ in failed))} failed the face check" if failed else ""
    return replace(found.landmarks, rejected=rejected), found.similarity, check


def _first_face(scan: Scan, template: Template, candidates, central: np.ndarray) -> tuple[Detection, FaceCheck, list[tuple[str, Detection]], bool]:
    """The first candidate that passes the face check, or a low-nosed one a later candidate agrees
    with (`_agreed`); its check; the (label, detection) of those that failed before it; and whether
    it was agreed. With none, the last candidate and its failed check."""
    failed, low = [], []
    for label, found in candidates:
        agreed = _agreed(template, found, label, low)
        if agreed is not None:
            return agreed[0], agreed[1], [f for f in failed if f[1] is not agreed[2]], True
        if label == SECOND_LOOK:
            continue
        check = check_face(scan, template, found.similarity, central)
        if check.is_face:
            break
        if check.low_nose:
            low.append((label, found, check))
        failed.append((label, found))
    return found, check, failed, False


def _agreed(template: Template, found: Detection, label: str, low: list[tuple[str, Detection, FaceCheck]]) -> tuple[Detection, FaceCheck, Detection] | None:
    """(noted detection, its check, the one it was) of the first earlier low-nosed candidate in `low`
    (`FaceCheck.low_nose`) that `found`, by `label`, places within DISAGREE_MM (mean over both
    masks' contact bands); else None. Two looks that agree on a face whose nose is flat (an ICT
    subject's tip 4.3-6.9 mm above the face around it) are not both misled by what misleads one."""
    for first, det, check in low:
        apart = _apart(template, det.similarity, found.similarity)
        if apart <= DISAGREE_MM:
            note = (f"{det.landmarks.note}; a low nose ({check.ridge_mm:.1f} mm above its sides, {check.below_mm:.1f} mm above "
                    f"the lip), and {label} places the mask region {apart:.1f} mm from where {first} does")
            return replace(det, landmarks=replace(det.landmarks, note=note)), check, det
    return None


def require_agreement(template: Template, shape: Similarity, failed: list[tuple[str, Detection]], doubt: str = "") -> None:
    """Refuse (InputError) when a detected face that failed the face check and the face's shape alone
    (`shape`, the fallback's similarity) put the template's mask region (both masks' contact bands)
    over DISAGREE_MM apart (mean): one of them lies on the wrong part of the face, and neither the
    geometry nor the face check can tell which (an ICT subject's nasal cushion landed on the lips,
    45 mm off, placed by the shape; a colour image 3 cm off its depth puts the detection off).
    `doubt`: what the refusal asks the user to check (`_size_doubt`); by default the colour's registration."""
    for label, det in failed:
        if det.landmarks.path == "fallback":
            continue
        apart = _apart(template, det.similarity, shape)
        if apart > DISAGREE_MM:
            raise InputError(
                f"the face found by {label} (which failed the face check) and the face's shape alone place the mask region "
                f"{apart:.0f} mm apart (at most {DISAGREE_MM:g}): one of them is on the wrong part of the face; "
                f"{doubt or 'does the colour image line up with the depth?'} give landmarks with --landmarks, or rescan facing the camera")


def _size_doubt(scan: Scan, failed: list[tuple[str, Detection]]) -> str:
    """Where a detected face failed the face check at a size no adult's face is (the template scaled
    outside SCALE_RANGE), what to ask of the scan's scale (`scale_question`); else ""."""
    odd = [(label, det.similarity.scale) for label, det in failed if not SCALE_RANGE[0] <= det.similarity.scale <= SCALE_RANGE[1]]
    if not odd:
        return ""
    label, scale = odd[0]
    return (f"the face found by {label} is x{scale:.2f} the template's size (an adult's: x{SCALE_RANGE[0]:g}-{SCALE_RANGE[1]:g}): "
            f"{scale_question(scan)};")


def _apart(template: Template, one: Similarity, other: Similarity) -> float:
    """Mean distance (mm) between the template's mask region (both masks' contact bands) placed by `one` and by `other`."""
    region = template.vertices[mask_region(template)]
    return float(np.linalg.norm(one.apply(region) - other.apply(region), axis=1).mean())


def landmark_free_alignment(scan: Scan, template: Template, rejected: str) -> tuple[Landmarks, Similarity, FaceCheck] | None:
    """The landmark-free (fallback) alignment, saying what was `rejected` for it, or None if it fails the face check."""
    landmarks, fit = fallback_alignment(scan, template)
    check = check_face(scan, template, fit, central_face(template))
    return (replace(landmarks, rejected=rejected), fit, check) if check.is_face else None


def _candidates(scan: Scan, template: Template, noise: LandmarkNoise) -> Iterator[tuple[str, Detection]]:
    """(label, alignment) to try in turn (each computed only if the one before fails the face check);
    `noise` on the landmarks of the scan's detections (`detect_landmarks`), not on the frontal looks."""
    looks = [(scan, "")]
    if not (scan.is_capture or scan.is_point_cloud) and (scan.colors is not None or scan.texture is not None):
        looks.append((replace(scan, colors=None, texture=None, uv=None), WITHOUT_COLOURS))
    for seen, without in looks:
        det = detect_landmarks(seen, template)
        if det is not None:
            det = with_noise(det, seen, template, noise)
            note = det.landmarks.note + (f"; on renders{without}" if without else "")
            yield det.landmarks.path + without, replace(det, landmarks=replace(det.landmarks, note=note))
            if scan.is_capture:
                second = detect_from_front(replace(scan, colors=None, texture=None, uv=None), template, det.similarity)
                if second is not None:
                    yield SECOND_LOOK, second
    landmarks, fit = fallback_alignment(scan, template)
    front = None if scan.is_capture else detect_from_front(_renderable(scan, fit), template, fit)
    if front is not None and 1.0 / FRONT_SIZE <= front.similarity.scale / fit.scale <= FRONT_SIZE:
        yield front.landmarks.path, front
    yield landmarks.path, Detection(landmarks, fit, len(landmarks.points))


def _renderable(scan: Scan, pose: Similarity) -> Scan:
    """A mesh to render: the scan itself, or a point cloud's points facing out of the face at `pose`."""
    return facing_surface(scan, pose.rotation[:, 2]) if scan.is_point_cloud else scan
