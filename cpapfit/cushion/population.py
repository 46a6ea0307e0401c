"""The adult population a stock cushion family is made for: POPULATION faces drawn from the
shipped ICT model (seed 0), each read for both masks by the sizing gauge's measure (`gauge_mm`)
and by the depth of the template seal curve's points along the mask axis (`seal_depth`).

The figures depend on no scan, so they are shipped (data/stock_population.npz, written by
`tools/build_stock_family.py`) rather than drawn at every start; the tests check the shipped
figures against a fresh draw.
"""

from functools import lru_cache

import numpy as np

from ..frozen import read_only
from ..ict import random_subject, template_truth
from ..shipped import npz, npz_bytes
from ..template import MASKS, load_template
from .contact import template_curve
from .generic import AXIS

POPULATION = 200
GAUGE = {"nasal": (129, 358), "oronasal": (168, 18)}  # template landmarks the gauge measures between
FILE = "stock_population.npz"


def gauge_mm(mask: str, vertices: np.ndarray) -> float:
    """The sizing gauge's measure (mm) of a `mask` on a face's template vertices (N, 3) mm."""
    a, b = GAUGE[mask]
    return float(np.linalg.norm(vertices[a] - vertices[b]))


def seal_depth(mask: str, vertices: np.ndarray) -> np.ndarray:
    """(K,) mm: the template seal curve's points on a face of template vertices (N, 3) mm, along
    the mask axis."""
    tri, bary = template_curve(mask)
    return np.einsum("kj,kjc->kc", bary, vertices[load_template().faces[tri]]) @ AXIS


def drawn() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{mask: ((POPULATION,) mm the gauge's measure, (POPULATION, K) mm each seal-curve point's
    depth)} of POPULATION faces drawn afresh, each made once for both masks."""
    rng = np.random.default_rng(0)
    faces = [template_truth(random_subject(rng, 0.0)[0]) for _ in range(POPULATION)]
    return {mask: (np.array([gauge_mm(mask, v) for v in faces]), np.array([seal_depth(mask, v) for v in faces])) for mask in MASKS}


@lru_cache(maxsize=1)
def population() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """`drawn`'s figures as shipped, read-only."""
    data = npz(__package__, FILE)
    return {mask: (read_only(data[f"{mask}_gauge"]), read_only(data[f"{mask}_depth"])) for mask in MASKS}


def population_gauge(mask: str) -> np.ndarray:
    """(POPULATION,) mm: the gauge's measure over the population's faces."""
    return population()[mask][0]


def population_bytes() -> bytes:
    """The .npz file of a fresh draw (`drawn`), as shipped."""
    return npz_bytes({f"{mask}_{name}": figures for mask, pair in drawn().items() for name, figures in zip(("gauge", "depth"), pair)})
