"""The pressure-compensated cushion: the rim's pre-load set from the tissue model so that, at the
recommended headgear force, the rim presses evenly; as sharp as the printable wall allows."""

from dataclasses import dataclass

import numpy as np
import trimesh

from .contact import Contact
from .generic import NOSE_TIP
from .nurbs import Cushion, CushionParams, design_cushion
from .solid import cushion_sheet, cushion_solid
from ..evaluation.fit import CushionFit, Face, FitParams, compensating_preload, fit_cushion, refined_preload
from ..thresholds import WALL_TOLERANCE
from ..frozen import freeze_arrays

SMOOTHING = (3.0, 6.0, 12.0)  # Gaussian widths tried for the pre-load, in seal-curve samples (of 128)
CORRECTIONS = 4  # the most times the pre-load is corrected by pressing the cushion it gives


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
    corrected by pressing the cushion it gives onto the face (`corrected`), and is smoothed by the
    least of SMOOTHING whose solid keeps the set wall thickness and does not fold into itself."""
    for smoothing in SMOOTHING:
        preload = compensating_preload(contact.curve, contact.normals, face.axis, warped, smoothing, fit_params)
        preload, cushion = corrected(preload, contact, face, warped, params, fit_params, smoothing)
        solid, wall, folds = cushion_solid(cushion, contact.normals)
        if wall >= WALL_TOLERANCE * params.wall_mm and folds == 0:
            break
    return cushion, Preload(preload, smoothing), solid, wall


def corrected(
    preload: np.ndarray, contact: Contact, face: Face, warped: np.ndarray, params: CushionParams, fit_params: FitParams,
    smoothing: float,
) -> tuple[np.ndarray, Cushion]:
    """((K,) mm, cushion): the pre-load (K,) mm along the seal curve corrected by what pressing the cushion it
    gives at the recommended force does (`refined_preload`, each correction smoothed by a Gaussian
    of `smoothing` seal-curve samples): once, then again while some of the covered rim presses
    outside the safe window and each correction brings more of it in, CORRECTIONS times at most (a
    narrow peak, where the correction is clipped and smoothed, takes several; where part of the rim
    cannot be brought in, in a crease whose pre-load stands at its limit, more let the rest out),
    and the cushion the corrected pre-load gives."""
    fit = pressed(preload, contact, face, warped, params, fit_params)[1]
    preload = refined_preload(preload, contact.curve, fit, smoothing, fit_params)
    cushion, fit = pressed(preload, contact, face, warped, params, fit_params)
    for _ in range(CORRECTIONS - 1):
        if fit.window_fraction == 1.0:
            break
        again = refined_preload(preload, contact.curve, fit, smoothing, fit_params)
        cushion_again, fit_again = pressed(again, contact, face, warped, params, fit_params)
        if fit_again.window_fraction <= fit.window_fraction:
            break
        preload, cushion, fit = again, cushion_again, fit_again
    return preload, cushion


def pressed(
    preload: np.ndarray, contact: Contact, face: Face, warped: np.ndarray, params: CushionParams, fit_params: FitParams,
) -> tuple[Cushion, CushionFit]:
    """The cushion with `preload` (K,) mm along the seal curve, and it pressed as a sheet onto
    `face` at its recommended force."""
    cushion = design_cushion(contact, face.axis, face.up, warped[NOSE_TIP], params, preload)
    return cushion, fit_cushion(cushion_sheet(cushion), face, params.flange_mm, None, fit_params)
