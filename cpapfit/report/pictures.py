"""Pictures of the template and registrations, ray-cast offscreen (no display needed); plots and
legends with matplotlib's Agg canvas."""

import io

import numpy as np
from matplotlib import colormaps
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from ..align.similarity import Similarity
from ..phantom import TEMPLATE_TO_CAMERA
from ..render import raycast, shade
from ..scan import Intrinsics
from ..template import Template

SKIN = np.array([0.85, 0.68, 0.58])
REGION_COLOURS = {"nasal": np.array([0.15, 0.45, 0.95]), "oronasal": np.array([0.95, 0.3, 0.15])}
CURVE_COLOUR = np.array([1.0, 1.0, 1.0])
RESIDUAL_MAX_MM = 1.0


def frontal_picture(vertices: np.ndarray, faces: np.ndarray, albedo: np.ndarray, width: int = 640, height: int = 480) -> np.ndarray:
    """(H, W, 3) uint8 frontal view of a face given in the template's frame (mm), albedo (N, 3) in [0, 1]."""
    f = 1.25 * height  # at 280 mm this frames the face from brow to chin
    intr = Intrinsics(width, height, f, f, (width - 1) / 2, (height - 1) / 2)
    cam = vertices @ TEMPLATE_TO_CAMERA.T + [0.0, 20.0, 280.0]
    return shade(raycast(cam, faces, intr), cam, faces, albedo)


def template_regions_picture(template: Template, width: int = 640, height: int = 480) -> np.ndarray:
    """(H, W, 3) uint8 frontal view of the template with each mask's contact band and centre curve."""
    albedo = np.tile(SKIN, (len(template.vertices), 1))
    for name, region in template.regions.items():
        albedo[region.band] = REGION_COLOURS[name]
        albedo[region.curve] = CURVE_COLOUR
    return frontal_picture(template.vertices, template.faces, albedo, width, height)


def residual_picture(vertices: np.ndarray, faces: np.ndarray, residual: np.ndarray, similarity: Similarity, title: str) -> bytes:
    """PNG bytes: the registered template seen from the front, coloured by the registration residual
    (mm, 0-1 mm scale; grey where unmatched), with a labelled colour bar."""
    frame = ((vertices - similarity.translation) @ similarity.rotation) / similarity.scale  # back to the template frame
    cmap = colormaps["viridis"]
    albedo = np.where(np.isfinite(residual)[:, None], cmap(np.clip(np.nan_to_num(residual), 0, RESIDUAL_MAX_MM) / RESIDUAL_MAX_MM)[:, :3], 0.6)
    image = frontal_picture(frame, faces, albedo)
    fig = Figure(figsize=(6.4, 4.8), dpi=100)
    ax = fig.subplots()
    ax.imshow(image)
    ax.set_axis_off()
    ax.set_title(title, fontsize=11)
    bar = fig.colorbar(ScalarMappable(Normalize(0, RESIDUAL_MAX_MM), cmap), ax=ax, fraction=0.04, pad=0.02)
    bar.set_label("distance to the scan (mm); grey: no scan data")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight", metadata={"Software": None})
    return buf.getvalue()
