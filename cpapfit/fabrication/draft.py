"""Demoulding analysis: the draft of a mould part's moulding surface along the way it is pulled.

A triangle of the moulding surface (outward normal n, pointing from the part into the cast) has
draft asin(-n . pull): positive where the part comes away from the cast as it moves, 0 on a wall
parallel to the pull (it scrapes along the cast), negative where the part would have to move
through the cast (an undercut). Casters want at least ~1 degree on rigid parts: a part meets the
target when at most MAX_UNDERCUT of its moulding area is undercut and at most MAX_BELOW_MIN has
less than MIN_DRAFT_DEG; where a part does not, the silicone has to flex out.
"""

from dataclasses import dataclass

import numpy as np

from ..thresholds import MAX_BELOW_MIN, MAX_UNDERCUT, MIN_DRAFT_DEG, UNDERCUT_DEG



@dataclass(frozen=True)
class Draft:
    """One mould part's moulding surface against its pull direction (unit, scan frame; and in words):
    its area, the fraction of that area with draft below MIN_DRAFT_DEG and the fraction undercut, and
    the least draft."""

    pull: np.ndarray
    pull_name: str
    area_mm2: float
    below_min_fraction: float
    undercut_fraction: float
    min_draft_deg: float

    @property
    def meets_target(self) -> bool:
        """At most MAX_UNDERCUT of the moulding area undercut and at most MAX_BELOW_MIN under MIN_DRAFT_DEG."""
        return self.undercut_fraction <= MAX_UNDERCUT and self.below_min_fraction <= MAX_BELOW_MIN

    def record(self) -> dict:
        """The fit.json entry."""
        return {
            "pull": self.pull_name, "pull_direction": np.round(self.pull, 4).tolist(), "moulding_area_mm2": round(self.area_mm2, 1),
            "draft_below_1deg_fraction": round(self.below_min_fraction, 4), "undercut_fraction": round(self.undercut_fraction, 4),
            "min_draft_deg": round(self.min_draft_deg, 2), "meets_target": self.meets_target,
        }


def draft_angles(vertices: np.ndarray, faces: np.ndarray, pull: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((M,) draft in degrees, (M,) area mm^2) of the triangles of a mesh wound outwards, pulled along `pull`."""
    cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    double_area = np.linalg.norm(cross, axis=1)
    normals = cross / np.maximum(double_area, 1e-300)[:, None]
    return np.degrees(np.arcsin(np.clip(-normals @ (pull / np.linalg.norm(pull)), -1.0, 1.0))), double_area / 2.0


def draft(vertices: np.ndarray, faces: np.ndarray, pull: np.ndarray, pull_name: str = "") -> Draft:
    """The draft summary of a moulding surface (triangles wound outwards from the part) pulled along `pull`."""
    angle, area = draft_angles(vertices, faces, pull)
    total = float(area.sum())
    return Draft(np.asarray(pull, dtype=float) / np.linalg.norm(pull), pull_name, total, float(area[angle < MIN_DRAFT_DEG].sum() / total),
                 float(area[angle < UNDERCUT_DEG].sum() / total), float(angle.min()))
