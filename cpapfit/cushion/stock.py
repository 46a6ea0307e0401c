"""Stock cushions: a family of sizes made for no one patient.

Each mask's cushion is the design on the ICT Face Model's mean face (its neutral, carried onto the
template), compensated for no one face but set back for the population: at each of the K seal-curve
points (`contact.SAMPLES`) its rim stands back along the mask axis by how far the
SET_BACK_PERCENTILE-th of the population's faces (`cushion.population`) stands out there against
the mean face (each face's depth taken from its own mean depth round the seal, where a mask
settles; less the least set back round the rim), so that the wall clears most faces' high points (the nasal bridge most) and the
membrane closes the rest; and a self-sealing membrane,
as stock silicone cushions have: every flap reaches SLACK_MM at the lowest CPAP pressure
(`envelope.flap_widths`, narrowed where its sheet would twist, `envelope.with_flaps`); no face's
sleep states are added. The flap is not measured from a real stock cushion. Sizes scale it
about the nasal bridge (template landmark 168, where a stock mask is seated) by the adult spread of the measure a sizing
gauge reads: for a nasal mask the nose's width at the wings (landmarks 129-358), for an oronasal
one the nasal bridge to just below the lower lip (168-18). Over the population, S, M and L are
the SIZE_PERCENTILES of that measure over its median; a nasal "W" (wide) is M made as wide as L.
Each size's solid ships (`stock_solid`; `tools/build_stock_family.py` makes them again).
Template frame (mm): x to the face's left, y up, z out of it.
"""

from functools import lru_cache

import numpy as np
import trimesh

from ..frozen import read_only
from ..ict import ict_face, load_ict, template_truth
from ..shipped import npz, npz_bytes
from ..template import load_template
from .envelope import LOWEST_CPAP_KPA, flap_widths, with_flaps
from .generic import AXIS, NOSE_TIP, UP, contact_on
from .nurbs import AROUND, Cushion, CushionParams, design_cushion
from .population import population, population_gauge, seal_depth
from .solid import cushion_solid

SIZE_PERCENTILES = {"S": 15.0, "M": 50.0, "L": 85.0}
SET_BACK_PERCENTILE = 85.0
SLACK_MM = 2.0  # every flap's reach at the lowest CPAP pressure: 10.5 mm of 0.5 mm silicone, reaching 5 mm at 10 cmH2O
BRIDGE = 168
SIZES = {"nasal": ("S", "M", "L", "W"), "oronasal": ("S", "M", "L")}


@lru_cache(maxsize=1)
def mean_face() -> np.ndarray:
    """(N, 3) mm: the template's vertices on the ICT mean face (template frame)."""
    model = load_ict()
    return template_truth(ict_face(model, np.zeros(0), {}))


@lru_cache(maxsize=2)
def set_back(mask: str) -> np.ndarray:
    """(K,) mm per seal-curve point: how far a stock rim stands back along the mask axis from the
    mean face (module docstring); read-only."""
    depth = population()[mask][1] - seal_depth(mask, mean_face())
    standing_out = np.percentile(depth - depth.mean(axis=1, keepdims=True), SET_BACK_PERCENTILE, axis=0)
    return read_only(standing_out - standing_out.min())


def size_scale(mask: str, size: str) -> np.ndarray:
    """(3,) the scale of a stock `size` about the nasal bridge, per template axis."""
    measures = population_gauge(mask)
    ratio = {s: np.percentile(measures, p) / np.median(measures) for s, p in SIZE_PERCENTILES.items()}
    if size == "W":
        return np.array([ratio["L"], 1.0, 1.0])
    return np.full(3, ratio[size])


SOLIDS_FILE = "stock_solids.npz"


def stock_solid(mask: str, size: str, params: CushionParams = CushionParams()) -> trimesh.Trimesh:
    """The solid (with its membrane) of the stock `size` of a `mask`, template frame, mm: as shipped
    (`solids_bytes`, the same to the bit) for the default `params`, else `stock_cushion`'s."""
    if params != CushionParams() or size not in SIZES.get(mask, ()):
        return stock_cushion(mask, size, params)[1]
    data = npz(__package__, SOLIDS_FILE)
    return trimesh.Trimesh(data[f"{mask}_{size}_vertices"], data[f"{mask}_{size}_faces"], process=False)


def solids_bytes() -> bytes:
    """The .npz file of every stock size's solid made afresh (`stock_cushion`, default parameters), as shipped."""
    solids = {(mask, size): stock_cushion(mask, size)[1] for mask in SIZES for size in SIZES[mask]}
    return npz_bytes({f"{mask}_{size}_{name}": array for (mask, size), solid in solids.items()
                      for name, array in (("vertices", solid.vertices), ("faces", solid.faces))})


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
    widths = flap_widths({LOWEST_CPAP_KPA: np.full(AROUND, SLACK_MM)}, contact, params.membrane_mm)
    cushion, solid, _ = with_flaps(contact, AXIS, UP, scaled[NOSE_TIP], params, back, widths, skin, wall)
    return cushion, solid
