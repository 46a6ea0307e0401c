"""Is a mesh a surface? Triangle soups, non-manifold tangles and degenerate meshes are refused.

A scan is a surface: most of its edges join exactly two triangles (the rest are its rim and the
rims of holes), few or none join more, and its triangles have area. A file that parses but is
none of these (random triangles, fins, every corner stored separately, all points on a line)
would otherwise be searched for a face for a long time and refused with a misleading reason.
"""

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..thresholds import MIN_SHARED_EDGES, MAX_NONMANIFOLD_EDGES, MAX_DEGENERATE, DEGENERATE_AREA



def check_surface(path: Path, vertices: np.ndarray, faces: np.ndarray, uses: np.ndarray) -> None:
    """Refuse (InputError) triangles of (N, 3) vertices that do not form a surface; `uses`: (E,) how
    many of them use each of their edges (`rims.edge_uses`)."""
    corners = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    degenerate = float((area <= DEGENERATE_AREA * np.ptp(vertices, axis=0).max() ** 2).mean())
    if degenerate > MAX_DEGENERATE:
        raise InputError(f"{path}: {100 * degenerate:.0f} % of the triangles have no area (a degenerate mesh); re-export the scan")
    if (uses > 2).mean() > MAX_NONMANIFOLD_EDGES:
        raise InputError(
            f"{path}: {100 * (uses > 2).mean():.0f} % of the edges join three or more triangles (non-manifold); "
            "this is not a single surface: repair the scan (e.g. remove duplicated or overlapping parts)"
        )
    if (uses == 2).mean() < MIN_SHARED_EDGES:
        raise InputError(
            f"{path}: only {100 * (uses == 2).mean():.0f} % of the edges join two triangles: the triangles do not form a "
            "surface (random triangles, or every triangle with its own corners: merge duplicate vertices)"
        )
