"""Initial alignment of the template on a scan: landmarks (user, detected, or none) and a similarity."""

from ..scan import Scan
from ..template import Template, central_face
from ..landmarks.detect import Detection, detect_from_front, detect_landmarks
from ..landmarks.fallback import fallback_alignment
from ..landmarks.types import Landmarks
from .check import FaceCheck, check_face, require_face
from .similarity import Similarity, fit_similarity


def initial_alignment(scan: Scan, template: Template, user: Landmarks | None = None) -> tuple[Landmarks, Similarity, FaceCheck]:
    """Landmarks, the similarity carrying the template onto the scan, and the face check.

    User landmarks override detection; without a detected face (on a mesh: or with one that does
    not lie on a face) the landmark-free fallback is used, and on a mesh a detection on a render
    from in front of the face it found replaces it. Any result that does not lie on a face is
    refused (InputError)."""
    central = central_face(template)
    if user is not None:
        fit = fit_similarity(template.vertices[user.template_index], user.points)
        landmarks = Landmarks(user.points, user.template_index, fit.weights, "user", "user landmarks file")
    else:
        detection = detect_landmarks(scan, template)
        retry = detection is not None and scan.is_mesh and not check_face(scan, template, detection.similarity, central).is_face
        if detection is None or retry:
            detection = _without_landmarks(scan, template)
        landmarks, fit = detection.landmarks, detection.similarity
    check = check_face(scan, template, fit, central)
    require_face(check, f"landmarks by {landmarks.path}")
    return landmarks, fit, check


def _without_landmarks(scan: Scan, template: Template) -> Detection:
    """The landmark-free fallback's alignment, or on a mesh the detection from in front of it."""
    landmarks, fit = fallback_alignment(scan, template)
    front = detect_from_front(scan, template, fit) if scan.is_mesh else None
    return front or Detection(landmarks, fit, len(landmarks.points))
