"""Captures made faulty on purpose, to trip the quality gates: depth holes over a region, a
colour image not registered to its depth. The truth is unchanged."""

from dataclasses import replace

import numpy as np

from ..render import raycast
from .camera import Phantom


def with_holes(ph: Phantom, region: np.ndarray, fraction: float, seed: int = 0, radius_px: tuple[float, float] = (4.0, 12.0)) -> Phantom:
    """The phantom with round depth holes (random radii in `radius_px`) centred on the region of
    template vertex indices `region`, added until at least `fraction` of the region's valid depth
    pixels are gone (a scan with holes over the mask). Colour and truth are unchanged."""
    hits = raycast(ph.surface, ph.faces, ph.intrinsics)
    in_region = np.isin(ph.faces, region).any(axis=1)
    pixels = hits.hit & in_region[np.where(hits.hit, hits.triangle, 0)] & (ph.depth_raw > 0)
    rows, cols = np.nonzero(pixels)
    rng = np.random.default_rng(seed)
    vv, uu = np.mgrid[: pixels.shape[0], : pixels.shape[1]]
    holes = np.zeros(pixels.shape, dtype=bool)
    while (holes & pixels).sum() < fraction * pixels.sum():
        k = rng.integers(len(rows))
        holes |= (uu - cols[k]) ** 2 + (vv - rows[k]) ** 2 <= rng.uniform(*radius_px) ** 2
    return replace(ph, depth_raw=np.where(holes, 0, ph.depth_raw).astype(np.uint16))


def with_colour_shift(ph: Phantom, px: int) -> Phantom:
    """The phantom with its colour image moved `px` pixels sideways (wrapping round): a capture whose
    colour is not registered to its depth. Depth and truth are unchanged."""
    return replace(ph, image=np.roll(ph.image, px, axis=1))
