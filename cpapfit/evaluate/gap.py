"""Gaps between a cushion's rim and the scanned skin, where the scan has data."""

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.ndimage import median_filter
from scipy.spatial import cKDTree

from ..frozen import freeze_arrays
from ..scan import Scan
from .rim import skin_under

SPACINGS = 1.5  # on a coarse scan, data within this many point spacings counts as present
CLOUD_REACH_MM = 5.0  # a rim point this near a cloud's nearest point (or SPACINGS local spacings) is measured to its tangent plane
NEAREST = 8  # scan points around a rim point: the scan's normal there; over its edge if any of them is
NORMAL_REACH_MM = 10.0  # a mesh's skin under a rim point is looked for along the normal from this far out


@dataclass(frozen=True)
class RimGap:
    """gap: (K,) mm from each rim point to the scan surface; covered: (K,) the scan has data under
    the point (`rim_gap`)."""

    gap: np.ndarray
    covered: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)

    def worst_stretch_mm(self, samples: int = 9) -> float:
        """The largest running median of the gap over `samples` consecutive covered rim points (mm;
        0 if none is covered): a stretch of rim off the skin, not one noisy sample of the scan."""
        g = self.gap[self.covered]
        return float(median_filter(g, size=min(samples, len(g)), mode="wrap").max()) if len(g) else 0.0

    def summary(self) -> dict:
        g = self.gap[self.covered]
        return {
            "rim_gap_median_mm": float(np.median(g)) if len(g) else None,
            "rim_gap_max_mm": float(g.max()) if len(g) else None,
            "rim_covered_fraction": float(self.covered.mean()),
        }


def rim_gap(rim: np.ndarray, normals: np.ndarray, scan: Scan, surface: trimesh.Trimesh | trimesh.PointCloud) -> RimGap:
    """Distances from (K, 3) rim points to the scan (mm), and where the scan covers them (none of
    the NEAREST scan points is on its `_edge`). A mesh (`surface`: `scan_surface`): to the skin
    under the flange, as `evaluate.rim` measures it (`skin_under`), along the scan's own normal
    there (the mean of the NEAREST points' normals, turned to agree with the (K, 3) unit skin
    `normals` of the registered face). Where no ray meets the mesh within NORMAL_REACH_MM, and for
    a point cloud: to the tangent plane at the nearest point, if within CLOUD_REACH_MM or SPACINGS
    times the points' spacing there, at most NORMAL_REACH_MM (not the gaps between the points: a
    cloud of a decimated mesh's vertices is sparse where the face is flat)."""
    tree = cKDTree(scan.vertices)
    plane = off_skin(scan, tree, rim, np.clip(SPACINGS * local_spacing(tree, rim), CLOUD_REACH_MM, NORMAL_REACH_MM))
    nearest = tree.query(rim, k=NEAREST)[1]
    covered = ~_edge(scan)[nearest].any(axis=1)
    if scan.is_point_cloud:
        return RimGap(plane, covered)
    around = scan.normals[nearest]  # (K, NEAREST, 3)
    skin = (around * np.sign(np.einsum("knj,kj->kn", around, normals))[..., None]).sum(axis=1)
    skin /= np.maximum(np.linalg.norm(skin, axis=1, keepdims=True), 1e-12)
    gap = np.abs(skin_under(rim, surface, skin, NORMAL_REACH_MM))
    return RimGap(np.where(gap <= NORMAL_REACH_MM, gap, plane), covered)


def _edge(scan: Scan) -> np.ndarray:
    """(N,) bool: scan points on a rim or hole of its surface, or in no triangle (a stray point of a
    surface; every point of a cloud is in none)."""
    return scan.rims if scan.is_point_cloud else scan.rims | (np.bincount(scan.faces.ravel(), minlength=len(scan.vertices)) == 0)


def local_spacing(tree: cKDTree, points: np.ndarray) -> np.ndarray:
    """(K,) mm: the mean distance from the scan point nearest each of (K, 3) points to its NEAREST
    nearest neighbours (on an even cloud about 1.3 times the nearest-neighbour spacing)."""
    nearest = tree.query(points)[1]
    return tree.query(tree.data[nearest], k=NEAREST + 1)[0][:, 1:].mean(axis=1)


def off_skin(scan: Scan, tree: cKDTree, points: np.ndarray, reach: float | np.ndarray) -> np.ndarray:
    """(K,) distance (mm) of points from the scan: to the tangent plane at the nearest scan point
    when that is within `reach` (mm, one or (K,); a coarse mesh's vertices are far apart), else to
    the point."""
    dist, idx = tree.query(points)
    plane = np.abs(np.einsum("ij,ij->i", points - scan.vertices[idx], scan.normals[idx]))
    return np.where(dist <= reach, plane, dist)
