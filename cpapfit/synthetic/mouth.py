"""An open mouth on a template-made face: the jaw turned about its hinge, the skin across the
mouth set back into the head as the dark inside a depth camera sees (template frame, mm)."""

import numpy as np
from matplotlib.path import Path as Polygon
from scipy.spatial.transform import Rotation

from ..template import Template


# Face Mesh's inner-lip contours, mouth corner to mouth corner.
UPPER_INNER_LIP = [78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308]
LOWER_INNER_LIP = [78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308]
JAW_HINGE_MM = (25.0, -85.0)  # the jaw's hinge from the upper inner lip (template frame, mm): 25 up, 85 back
CAVITY_MM = 20.0  # how far behind the lips an open mouth's inside lies
MOUTH_INSIDE = np.array([0.12, 0.04, 0.04])  # its albedo


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
