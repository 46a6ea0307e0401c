"""Lying on the back: the face's soft tissue slides as gravity turns from down the face to into it.

Measured from upright to supine by 3D surface scans of 175 adults (Frank et al., Aesthetic Plast
Surg 2022;46:2237-45): the skin moves cranially and laterally, the lateral face more than the
medial face (by 0.88 mm cranially, 0.76 mm laterally) and the lower face more than the middle face
(by 1.17 mm and 1.37 mm). Here the medial middle face (the nose and the nasal bridge, where the mask
bears on thin tissue over bone, and by which it is held) stays, and each template vertex moves by
those differences, weighted by how far it lies beyond the mid-pupillary line (lateral) and below
the corners of the mouth (lower), each blended over BLEND_MM (the midline does not move sideways,
and the lateral slide grows over BLEND_MM from it): 2.05 mm cranially and 2.13 mm
laterally at the angle of the jaw, less their part along the template's normal. The motion is along
the skin: the skin slides over itself and changes shape only where the slide varies across it.
An elastic layer bonded to bone would sag under its own weight only rho g h^2 / (2 G), about 0.2 mm
for 15 mm of cheek of E 16 kPa; the measured slide is larger, as the face's fat compartments slide
on their fascia, so the measured figures are used.
"""

from functools import lru_cache

import numpy as np

from ..template import load_template

LATERAL_MM = (0.76, 1.37)  # lateral slide of the lateral face beyond the medial, of the lower face beyond the middle
CRANIAL_MM = (0.88, 1.17)  # cranial slide, the same
BLEND_MM = 20.0  # the regions' borders are blended over this width
EYE_CORNERS = (33, 133, 362, 263)  # template landmarks: the right eye's outer and inner corner, the left's inner and outer
MOUTH_CORNERS = (61, 291)


@lru_cache(maxsize=1)
def template_supine() -> np.ndarray:
    """(N, 3) mm: the skin's slide from upright to lying on the back on the template (template frame:
    x to the face's left, y up, z out of the face; template vertex order)."""
    template = load_template()
    v, lm = template.vertices, template.landmarks
    pupil_x = 0.5 * np.mean(np.abs(lm[list(EYE_CORNERS), 0]))
    lateral = _blend(np.abs(v[:, 0]) - pupil_x)
    lower = _blend(np.mean(lm[list(MOUTH_CORNERS), 1]) - v[:, 1])
    weights = np.column_stack([lateral, lower])
    outwards = np.sign(v[:, 0]) * _blend(np.abs(v[:, 0]) - 0.5 * BLEND_MM)  # the midline does not move sideways
    slide = np.column_stack([outwards * (weights @ LATERAL_MM), weights @ CRANIAL_MM, np.zeros(len(v))])
    normals = template.mesh().vertex_normals
    out = slide - np.einsum("ij,ij->i", slide, normals)[:, None] * normals
    out.flags.writeable = False
    return out


def _blend(beyond_mm: np.ndarray) -> np.ndarray:
    """(N,) 0 to 1 as a point lies from BLEND_MM / 2 inside a border to as far beyond it (smoothstep)."""
    t = np.clip(beyond_mm / BLEND_MM + 0.5, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)
