"""The soft-tissue model: an elastic foundation with per-region stiffness, in series with the
cushion's own compliance.

Each facial region is a layer of soft tissue of Young's modulus E (kPa) and thickness h (mm)
bonded to bone; it presses back p = k * indentation, k (kPa/mm) the mean pressure under a rigid
strip as wide as the seal flange (5 mm) pressed into that layer, computed by the finite-element
reference (`calibration.strip_stiffness`, plane strain, Poisson 0.49): 3.2-4.0 times the E / h a
Winkler foundation would say, as a nearly incompressible layer cannot squeeze out from under the
strip. E values are the literature's indentation figures (cheek ~16, below the cheekbone ~27,
chin ~53, cheekbone ~65 kPa); thicknesses are typical soft-tissue depths over bone. Over the nasal
bones the layer is only ~3 mm thick, so the bridge is stiff: the classic pressure sore. Regions
are anchored on template landmarks and blended smoothly (Gaussian in the template's mm), so any
point of the face gets a stiffness. The cushion's seal flange is a spring in series (kPa per mm
of flange compression): the finite-element slices of designed walls bound it between a flange
sliding on the skin and one gripping it (`bench/RESULTS.md`); 1 kPa/mm lies between.
"""

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..frozen import freeze_arrays
from ..template import load_template

STRIP_MM = 5.0  # the flange width the layers' stiffness is computed under


class Region(NamedTuple):
    """A facial region's tissue: E (kPa), depth over bone (mm), its layer's stiffness (kPa/mm) under
    a STRIP_MM strip (`calibration.strip_stiffness`, 48 cells across the depth), and the template
    landmarks it is anchored on."""

    youngs_kpa: float
    depth_mm: float
    stiffness_kpa_per_mm: float
    anchors: tuple


REGIONS = {
    "nasal bridge": Region(40.0, 3.0, 46.46, (6, 168, 197, 195, 5)),
    "side of the nose": Region(25.0, 8.0, 10.29, (129, 358, 48, 278)),
    "upper lip": Region(20.0, 12.0, 6.07, (2, 164, 0, 37, 267)),
    "cheek": Region(16.0, 15.0, 4.22, (36, 266, 100, 329, 205, 425)),
    "below the cheekbone": Region(27.0, 14.0, 7.42, (187, 411, 147, 376, 212, 432, 214, 434)),
    "cheekbone": Region(65.0, 7.0, 30.02, (116, 345, 123, 352, 50, 280)),
    "chin": Region(53.0, 10.0, 18.31, (18, 200, 199, 175, 152, 135, 364)),
}


@dataclass(frozen=True)
class TissueModel:
    """Parameters of the tissue and cushion springs (kPa, mm). `regions`: name -> `Region`; `blend_mm`:
    Gaussian width of the blending between anchors; `cushion_kpa_per_mm`: effective stiffness of
    the seal flange per unit contact area."""

    regions: dict = field(default_factory=lambda: dict(REGIONS))
    blend_mm: float = 8.0
    cushion_kpa_per_mm: float = 1.0

    def describe(self) -> dict:
        """The model as it goes into fit.json."""
        return {
            "model": f"elastic foundation per region, k = the stiffness of a layer of E and thickness on bone under a "
                     f"rigid {STRIP_MM:g} mm strip (finite elements, plane strain, Poisson 0.49), blended between "
                     "template landmarks, in series with the cushion flange's stiffness",
            "regions": {name: {"youngs_modulus_kpa": r.youngs_kpa, "thickness_mm": r.depth_mm,
                               "stiffness_kpa_per_mm": r.stiffness_kpa_per_mm} for name, r in self.regions.items()},
            "blend_mm": self.blend_mm,
            "cushion_kpa_per_mm": self.cushion_kpa_per_mm,
        }


@dataclass(frozen=True)
class Stiffness:
    """Per rim point: tissue (K,) kPa/mm, effective (K,) kPa/mm (tissue and cushion in series),
    region (K,) name of the dominant region."""

    tissue: np.ndarray
    effective: np.ndarray
    region: tuple

    def __post_init__(self):
        freeze_arrays(self)


def stiffness(vertex: np.ndarray, model: TissueModel = TissueModel()) -> Stiffness:
    """Stiffness under (K,) points on the patient, each located on the face by its nearest
    template vertex (`vertex` (K,) indices into the template, e.g. the nearest registered one)."""
    template = load_template()
    where = template.vertices[vertex]  # the points' places on the template face
    names = list(model.regions)
    log_k = np.log([r.stiffness_kpa_per_mm for r in model.regions.values()])
    weight = np.stack([_closeness(where, template.vertices[list(model.regions[n].anchors)], model.blend_mm) for n in names], axis=1)
    tissue = np.exp((weight * log_k).sum(axis=1) / weight.sum(axis=1))
    effective = 1.0 / (1.0 / tissue + 1.0 / model.cushion_kpa_per_mm)
    return Stiffness(tissue, effective, tuple(names[i] for i in weight.argmax(axis=1)))


def _closeness(points: np.ndarray, anchors: np.ndarray, width_mm: float) -> np.ndarray:
    """(K,) Gaussian weight of the nearest anchor, floored so far points still blend."""
    d = np.linalg.norm(points[:, None] - anchors[None], axis=2).min(axis=1)
    return np.exp(-0.5 * (d / width_mm) ** 2) + 1e-12
