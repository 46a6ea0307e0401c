"""Stock cushions: a family of sizes made for no one patient.

Each mask's cushion is the design on the ICT Face Model's mean face (its neutral, carried onto the
template), compensated for no one face but set back for the population: at each of the K seal-curve
points (`contact.SAMPLES`) its rim stands back along the mask axis by how far the
SET_BACK_PERCENTILE-th of POPULATION faces stands out there against the mean face (each face's
depth taken from its own mean depth round the seal, where a mask settles; less the least set back
round the rim), so that the wall clears most faces' high points (the nasal bridge most) and the
membrane closes the rest; and a self-sealing membrane,
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

from ..frozen import read_only
from ..ict import ict_face, load_ict, random_subject, template_truth
from ..template import load_template
from .contact import template_curve
from .envelope import LOWEST_CPAP_KPA, REACH_MM, flap_widths, with_flaps
from .generic import AXIS, NOSE_TIP, UP, contact_on
from .nurbs import AROUND, Cushion, CushionParams, design_cushion
from .solid import cushion_solid

POPULATION = 200
SIZE_PERCENTILES = {"S": 15.0, "M": 50.0, "L": 85.0}
SET_BACK_PERCENTILE = 85.0
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


@lru_cache(maxsize=1)
def population() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{mask: ((POPULATION,) mm the gauge's measure, (POPULATION, K) mm each seal-curve point's
    depth along the mask axis, `_seal_depth`)} over faces drawn from the shipped ICT model (seed 0),
    each face made once for both masks; read-only."""
    rng = np.random.default_rng(0)
    faces = [template_truth(random_subject(rng, 0.0)[0]) for _ in range(POPULATION)]
    return {mask: (read_only(np.array([gauge_mm(mask, v) for v in faces])), read_only(np.array([_seal_depth(mask, v) for v in faces])))
            for mask in SIZES}


def population_gauge(mask: str) -> np.ndarray:
    """(POPULATION,) mm: the gauge's measure over the population's faces (`population`)."""
    return population()[mask][0]


@lru_cache(maxsize=2)
def set_back(mask: str) -> np.ndarray:
    """(K,) mm per seal-curve point: how far a stock rim stands back along the mask axis from the
    mean face (module docstring); read-only."""
    depth = population()[mask][1] - _seal_depth(mask, mean_face())
    standing_out = np.percentile(depth - depth.mean(axis=1, keepdims=True), SET_BACK_PERCENTILE, axis=0)
    return read_only(standing_out - standing_out.min())


def _seal_depth(mask: str, vertices: np.ndarray) -> np.ndarray:
    """(K,) mm: the template seal curve's points on a face of template vertices (N, 3) mm, along
    the mask axis."""
    tri, bary = template_curve(mask)
    return np.einsum("kj,kjc->kc", bary, vertices[load_template().faces[tri]]) @ AXIS


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
    back = -set_back(mask) * scale[2]  # a pre-load out of the skin
    wall = cushion_solid(design_cushion(contact, AXIS, UP, scaled[NOSE_TIP], params, back), contact.normals)[0]
    widths = flap_widths({LOWEST_CPAP_KPA: np.full(AROUND, REACH_MM[0])}, contact, params.membrane_mm)
    cushion, solid, _ = with_flaps(contact, AXIS, UP, scaled[NOSE_TIP], params, back, widths, skin, wall)
    return cushion, solid
