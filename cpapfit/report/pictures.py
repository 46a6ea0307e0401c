"""Pictures (RGB uint8 arrays) of the template and scans, ray-cast offscreen: no display needed."""

import numpy as np

from ..phantom import TEMPLATE_TO_CAMERA
from ..render import raycast, shade
from ..scan import Intrinsics
from ..template import Template

SKIN = np.array([0.85, 0.68, 0.58])
REGION_COLOURS = {"nasal": np.array([0.15, 0.45, 0.95]), "oronasal": np.array([0.95, 0.3, 0.15])}
CURVE_COLOUR = np.array([1.0, 1.0, 1.0])


def template_regions_picture(template: Template, width: int = 640, height: int = 480) -> np.ndarray:
    """(H, W, 3) uint8 frontal view of the template with each mask's contact band and centre curve."""
    f = 1.25 * height  # at 280 mm this frames the face from brow to chin
    intr = Intrinsics(width, height, f, f, (width - 1) / 2, (height - 1) / 2)
    vertices = template.vertices @ TEMPLATE_TO_CAMERA.T + [0.0, 20.0, 280.0]
    albedo = np.tile(SKIN, (len(vertices), 1))
    for name, region in template.regions.items():
        albedo[region.band] = REGION_COLOURS[name]
        albedo[region.curve] = CURVE_COLOUR
    return shade(raycast(vertices, template.faces, intr), vertices, template.faces, albedo)
