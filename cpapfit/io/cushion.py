"""A cushion mesh in (for `cpapfit evaluate`): millimetres, in the scan's frame, as `design` writes it."""

from pathlib import Path

import numpy as np
import trimesh

from ..errors import InputError, UnitsError
from .mesh import read_geometry
from ..thresholds import CUSHION_SIZE_MM



def load_cushion(path: Path) -> trimesh.Trimesh:
    """The cushion as a triangle mesh (mm), or an InputError / UnitsError saying what is wrong."""
    geom = read_geometry(Path(path))
    if not isinstance(geom, trimesh.Trimesh) or len(geom.faces) < 4:
        raise InputError(f"{path}: a cushion must be a triangle mesh (STL, 3MF-exported STL, PLY, OBJ)")
    if not np.isfinite(geom.vertices).all():
        raise InputError(f"{path}: the cushion has NaN or infinite vertices")
    size = float(np.ptp(geom.vertices, axis=0).max())
    if not CUSHION_SIZE_MM[0] <= size <= CUSHION_SIZE_MM[1]:
        raise UnitsError(
            f"{path}: the cushion is {size:.4g} units across; cpapfit reads cushions in millimetres "
            f"({CUSHION_SIZE_MM[0]:.0f}-{CUSHION_SIZE_MM[1]:.0f} mm), in the scan's frame as `cpapfit design` writes them"
        )
    return geom
