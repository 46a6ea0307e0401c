"""The pressure-compensated cushion: the rim's pre-load set from the tissue model so that, at the
recommended headgear force, the rim presses evenly; as sharp as the printable wall allows."""

from dataclasses import dataclass

import numpy as np
import trimesh

from .contact import Contact
from .generic import NOSE_TIP
from .nurbs import Cushion, CushionParams, design_cushion
from .solid import cushion_sheet, cushion_solid
from ..evaluation.fit import Face, FitParams, compensating_preload, fit_cushion, refined_preload
from ..thresholds import WALL_TOLERANCE
from ..frozen import freeze_arrays

SMOOTHING = (3.0, 6.0, 12.0)  # Gaussian widths tried for the pre-load, in seal-curve samples (of 128)


@dataclass(frozen=True)
class Preload:
    """The compensating pre-load: mm (K,) along the seal curve, and its smoothing (curve samples)."""

    mm: np.ndarray
    smoothing: float

    def __post_init__(self):
        freeze_arrays(self)


def compensated_cushion(
    contact: Contact, face: Face, warped: np.ndarray, params: CushionParams, fit_params: FitParams,
) -> tuple[Cushion, Preload, trimesh.Trimesh, float]:
    """(cushion, pre-load, solid, thinnest wall mm). The pre-load comes from the tissue model, is
    corrected once by pressing the cushion it gives onto the face, and is smoothed by the least
    of SMOOTHING whose solid keeps the set wall thickness and does not fold into itself."""
    for smoothing in SMOOTHING:
        preload = compensating_preload(contact.curve, contact.normals, face.axis, warped, smoothing, fit_params)
        first = design_cushion(contact, face.axis, face.up, warped[NOSE_TIP], params, preload)
        pressed = fit_cushion(cushion_sheet(first), face, params.flange_mm, None, fit_params)
        preload = refined_preload(preload, contact.curve, pressed, smoothing, fit_params)
        cushion = design_cushion(contact, face.axis, face.up, warped[NOSE_TIP], params, preload)
        solid, wall, folds = cushion_solid(cushion, contact.normals)
        if wall >= WALL_TOLERANCE * params.wall_mm and folds == 0:
            break
    return cushion, Preload(preload, smoothing), solid, wall
