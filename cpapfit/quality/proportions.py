"""The registered face's size and its depth for its breadth, both relative to the template's.

A misstated scale passes every other check: a capture's depth scale or a mesh's units off by a
factor k scale the whole face, and the mask, by k; intrinsics whose focal length is off by k
shrink the face's width and height by k but not its depth. The shape fits as well as ever, so only
proportions can tell. The registered face (template vertex order) is brought back to the
template's frame and size by the similarity, and one linear map is fitted from the template to
it over the vertices matched to the scan; its diagonal is the stretch along the template's axes
(x across, y up, z out of the face).

size: the face's width and height scale (geometric mean) against the template's, an adult man's
    (synthetic adults 0.83-1.16 over 959 designs, the shared real scans 0.96-0.98);
depth_ratio: its depth scale over its size (synthetic adults 0.86-1.12, the shared scans 0.97-0.99;
    1 000 ICT Face Model subjects 0.65-1.29 over the part of the face a capture sees, 0.79-1.23 over
    the whole template: bench/ict_proportions.py).
A focal length 1.3 times too long reads 1.17-1.29 and a size 1.3 times too small; 1.5 times, 1.29-1.49.
Twice too long, the detected face fails the face check and the template placed by the shape alone
follows the face loosely: the depth ratio reads anything from 0.88 to 1.70, the size 0.58-0.72
(bench/RESULTS.md).
"""

from dataclasses import dataclass

import numpy as np

from ..align.nonrigid import Registration
from ..similarity import Similarity
from ..thresholds import MIN_MATCHED



@dataclass(frozen=True)
class Proportions:
    """The face against the template (dimensionless; NaN when too little of it was matched, and the
    depth ratio NaN when the map has no breadth)."""

    size: float
    depth_ratio: float


def proportions(template_vertices: np.ndarray, similarity: Similarity, registration: Registration) -> Proportions:
    """The proportions of the registered face, from the (n, 3) mm template vertices it warped."""
    keep = registration.valid
    if keep.sum() < MIN_MATCHED:
        return Proportions(np.nan, np.nan)
    source = template_vertices[keep]
    face = (registration.vertices[keep] - similarity.translation) @ similarity.rotation / similarity.scale
    design = np.hstack([source - source.mean(axis=0), np.ones((len(source), 1))])
    linear = np.linalg.lstsq(design, face, rcond=None)[0][:3].T
    across, up, depth = np.diag(linear)
    breadth = float(np.sqrt(max(across * up, 0.0)))
    return Proportions(similarity.scale * breadth, float(depth) / breadth if breadth > 0 else np.nan)
