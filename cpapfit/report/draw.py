"""Marks drawn into pictures (PIL): closed rims with a colour per point, and dots."""

import numpy as np
from PIL import Image, ImageDraw


def draw_loop(image: np.ndarray, pixels: np.ndarray, visible: np.ndarray, colours: np.ndarray, width: int = 7) -> np.ndarray:
    """Copy of an (H, W, 3) uint8 picture with a closed polyline through (K, 2) pixels drawn in (K, 3)
    uint8 colours, point k's colour from it halfway to each neighbour; hidden points break the line."""
    im = Image.fromarray(image)
    draw = ImageDraw.Draw(im)
    k = len(pixels)
    mid = 0.5 * (pixels + np.roll(pixels, -1, axis=0))
    for i in np.flatnonzero(visible):
        fill = tuple(int(c) for c in colours[i])
        for j, end in (((i + 1) % k, mid[i]), ((i - 1) % k, mid[i - 1])):
            if visible[j]:
                draw.line([tuple(pixels[i]), tuple(end)], fill=fill, width=width)
        r = width / 2
        draw.ellipse([pixels[i, 0] - r, pixels[i, 1] - r, pixels[i, 0] + r, pixels[i, 1] + r], fill=fill)
    return np.asarray(im)


def draw_dots(image: np.ndarray, pixels: np.ndarray, colours: np.ndarray, radius: float = 4.0) -> np.ndarray:
    """Copy of an (H, W, 3) uint8 picture with dots at (K, 2) pixels in (K, 3) uint8 colours, outlined in black."""
    im = Image.fromarray(image)
    draw = ImageDraw.Draw(im)
    for (u, v), c in zip(pixels, colours):
        draw.ellipse([u - radius, v - radius, u + radius, v + radius], fill=tuple(int(x) for x in c), outline=(0, 0, 0))
    return np.asarray(im)
