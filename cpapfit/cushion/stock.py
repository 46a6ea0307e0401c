"""Stock cushions: a family of sizes made for no one patient.

Each mask's cushion is the design on the ICT Face Model's mean face (its neutral, carried onto the
template), with no pre-load (a stock cushion is compensated for no one) and a self-sealing membrane,
as stock silicone cushions have, sized by the custom cushion's rule for its awake slack: every
flap reaches REACH_MM[0] at the lowest CPAP pressure (`envelope.flap_widths`, narrowed where its
sheet would twist, `envelope.with_flaps`); no face's sleep states are added. The flap is
not measured from a real stock cushion. Sizes scale it about the nasal bridge
(template landmark 168, where a stock mask is seated) by the adult spread of the measure a sizing
gauge reads: for a nasal mask the nose's width at the wings (landmarks 129-358), for an oronasal
one the nasal bridge to just below the lower lip (168-18). Over POPULATION faces drawn from the
shipped ICT model, S, M and L are the SIZE_PERCENTILES of that measure over its median; a nasal
"W" (wide) is M made as wide as L. Template frame (mm): x to the face's left, y up, z out of it.
"""

from functools import lru_cache

import numpy as np
import trimesh

from ..ict import ict_face, load_ict, random_subject, template_truth
from ..template import load_template
from .envelope import LOWEST_CPAP_KPA, REACH_MM, flap_widths, with_flaps
from .generic import AXIS, NOSE_TIP, UP, contact_on
from .nurbs import AROUND, Cushion, CushionParams, design_cushion
from .solid import cushion_solid

POPULATION = 200
SIZE_PERCENTILES = {"S": 15.0, "M": 50.0, "L": 85.0}
GAUGE = {"nasal": (129, 358), "oronasal": (168, 18)}  # template landmarks the gauge measures between
BRIDGE = 168
SIZES = {"nasal": ("S", "M", "L", "W"), "oronasal": ("S", "M", "L")}


@lru_cache(maxsize=1)
def mean_face() -> np.ndarray:
    """(N, 3) mm: the template's vertices on the ICT mean face (template frame)."""
    model = load_ict()
    return template_truth(ict_face(model, np.zeros(0), {}))


def gauge_mm(mask: str, vertices: np.ndarray) -> float:
    """The sizing gauge's measure (mm) of a `mask` on a face's template vertices (N, 3) mm."""
    a, b = GAUGE[mask]
    return float(np.linalg.norm(vertices[a] - vertices[b]))


@lru_cache(maxsize=2)
def population_gauge(mask: str) -> np.ndarray:
    """(POPULATION,) mm: the gauge's measure over faces drawn from the shipped ICT model (seed 0)."""
    rng = np.random.default_rng(0)
    return np.array([gauge_mm(mask, template_truth(random_subject(rng, 0.0)[0])) for _ in range(POPULATION)])


def size_scale(mask: str, size: str) -> np.ndarray:
    """(3,) the scale of a stock `size` about the nasal bridge, per template axis."""
    measures = population_gauge(mask)
    ratio = {s: np.percentile(measures, p) / np.median(measures) for s, p in SIZE_PERCENTILES.items()}
    if size == "W":
        return np.array([ratio["L"], 1.0, 1.0])
    return np.full(3, ratio[size])


@lru_cache(maxsize=8)
def stock_cushion(mask: str, size: str, params: CushionParams = CushionParams()) -> tuple[Cushion, trimesh.Trimesh]:
    """(the cushion, its solid with the membrane) of the stock `size` of a `mask` ("nasal": S, M, L, W;
    "oronasal": S, M, L), template frame, mm."""
    if size not in SIZES[mask]:
        raise ValueError(f"no stock size {size!r} of the {mask} cushion (sizes: {', '.join(SIZES[mask])})")
    face = mean_face()
    scale = size_scale(mask, size)
    bridge = face[BRIDGE]
    scaled = (face - bridge) * scale + bridge
    skin = trimesh.Trimesh(scaled, load_template().faces, process=False)
    contact = contact_on(mask, skin)
    wall = cushion_solid(design_cushion(contact, AXIS, UP, scaled[NOSE_TIP], params), contact.normals)[0]
    widths = flap_widths({LOWEST_CPAP_KPA: np.full(AROUND, REACH_MM[0])}, contact, params.membrane_mm)
    cushion, solid, _ = with_flaps(contact, AXIS, UP, scaled[NOSE_TIP], params, None, widths, skin, wall)
    return cushion, solid
