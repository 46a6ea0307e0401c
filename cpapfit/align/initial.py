"""Initial alignment of the template on a scan: landmarks (user, detected, or none) and a similarity."""

from ..scan import Scan
from ..template import Template, central_face
from ..landmarks.detect import detect_landmarks
from ..landmarks.fallback import fallback_alignment
from ..landmarks.types import Landmarks
from .check import FaceCheck, check_face, require_face
from .similarity import Similarity, fit_similarity


def initial_alignment(scan: Scan, template: Template, user: Landmarks | None = None) -> tuple[Landmarks, Similarity, FaceCheck]:
    """Landmarks, the similarity carrying the template onto the scan, and the face check.

    User landmarks override detection; without a detected face the landmark-free fallback is
    used. Any result that does not lie on a face is refused (InputError)."""
    if user is not None:
        fit = fit_similarity(template.vertices[user.template_index], user.points)
        landmarks = Landmarks(user.points, user.template_index, fit.weights, "user", "user landmarks file")
    else:
        detection = detect_landmarks(scan, template)
        if detection is not None:
            landmarks, fit = detection.landmarks, detection.similarity
        else:
            landmarks, fit = fallback_alignment(scan, template)
    check = check_face(scan, template, fit, central_face(template))
    require_face(check, f"landmarks by {landmarks.path}")
    return landmarks, fit, check
