"""Gaps between a cushion's rim and the scanned skin, where the scan has data.

The skin under a rim point is a quadric fitted to the scan's points within FOOTPRINT_MM of it: a
flange rests on skin that wide, not on one noisy depth sample (σ 0.35 mm at 600 mm; a rim exactly
on the true skin read up to 0.56 mm from a median of seven ray hits on the scan's triangles). Where
the scan is too coarse for that (a mesh or cloud with points 3 mm apart), the scan's own triangles
or tangent planes are the skin."""

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.ndimage import median_filter
from scipy.spatial import cKDTree

from ..frozen import freeze_arrays
from ..scan import Scan
from ..tangents import across
from .rim import skin_under

SPACINGS = 1.5  # on a coarse scan, data within this many point spacings counts as present
CLOUD_REACH_MM = 5.0  # a rim point this near a cloud's nearest point (or SPACINGS local spacings) is measured to its tangent plane
NEAREST = 8  # scan points around a rim point: the scan's normal there; over its edge if any of them is
NORMAL_REACH_MM = 10.0  # a mesh's skin under a rim point is looked for along the normal from this far out
FOOTPRINT_MM = 4.0  # the skin under a rim point: a quadric through the scan points this near it (a flange is 5 mm wide)
MIN_FIT = 15  # fewer scan points that near (a coarse scan): the skin is the scan's triangles or tangent planes
OUTLIER = 3.0  # scan points farther from the first quadric than this many robust sigmas are dropped before the second


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


def rim_gap(rim: np.ndarray, normals: np.ndarray | None, scan: Scan, surface: trimesh.Trimesh | trimesh.PointCloud) -> RimGap:
    """Distances from (K, 3) rim points to the scan (mm), and where the scan covers them (none of
    the NEAREST scan points is on its `_edge`). The skin is the `quadric_gap` fit across the scan's
    normal there (the mean of the NEAREST points' normals, turned to agree with the (K, 3) unit skin
    `normals` of the registered face, or with the nearest point's). Where the scan is too coarse for
    it: a mesh (`surface`: `scan_surface`) the skin under the flange as `evaluation.rim` finds it
    (`skin_under`); where no ray meets the mesh within NORMAL_REACH_MM, and for a point cloud, the
    tangent plane at the nearest point, if within CLOUD_REACH_MM or SPACINGS times the points'
    spacing there, at most NORMAL_REACH_MM (not the gaps between the points: a cloud of a decimated
    mesh's vertices is sparse where the face is flat)."""
    tree = cKDTree(scan.vertices)
    plane = off_skin(scan, tree, rim, data_reach(tree, rim, CLOUD_REACH_MM))
    nearest = tree.query(rim, k=NEAREST)[1]
    covered = ~_edge(scan)[nearest].any(axis=1)
    around = scan.normals[nearest]  # (K, NEAREST, 3)
    agree = around[:, 0] if normals is None else normals
    skin = (around * np.sign(np.einsum("knj,kj->kn", around, agree))[..., None]).sum(axis=1)
    skin /= np.maximum(np.linalg.norm(skin, axis=1, keepdims=True), 1e-12)
    gap = quadric_gap(rim, skin, scan, tree)
    coarse = np.isnan(gap)  # too few scan points for the fit
    gap[coarse] = plane[coarse]
    if coarse.any() and not scan.is_point_cloud:
        rays = np.abs(skin_under(rim[coarse], surface, skin[coarse], NORMAL_REACH_MM))
        gap[coarse] = np.where(rays <= NORMAL_REACH_MM, rays, plane[coarse])
    return RimGap(gap, covered)


def quadric_gap(points: np.ndarray, axes: np.ndarray, scan: Scan, tree: cKDTree) -> np.ndarray:
    """(K,) mm from (K, 3) points to the skin under them: a quadric height field over the plane across
    the (K, 3) unit `axes`, least squares through the scan points within FOOTPRINT_MM that face the
    same side, fitted again without the points OUTLIER robust sigmas off it (stray depth samples).
    NaN where fewer than MIN_FIT points are there."""
    gap = np.full(len(points), np.nan)
    sides = np.stack(across(axes), axis=1)  # (K, 2, 3)
    for k, idx in enumerate(tree.query_ball_point(points, FOOTPRINT_MM)):
        idx = np.asarray(idx, dtype=int)
        idx = idx[scan.normals[idx] @ axes[k] > 0]
        if len(idx) >= MIN_FIT:
            offsets = scan.vertices[idx] - points[k]
            gap[k] = _height(offsets @ sides[k].T, offsets @ axes[k])
    return gap


def _height(uv: np.ndarray, w: np.ndarray) -> float:
    """mm from the origin to the quadric w(u, v) fitted to (M, 2) uv and (M,) w: its height at the
    origin, times the cosine of its slope there."""
    u, v = uv.T
    design = np.column_stack([np.ones_like(u), u, v, u * u, u * v, v * v])
    coef = np.linalg.lstsq(design, w, rcond=None)[0]
    off = np.abs(w - design @ coef)
    keep = off <= OUTLIER * 1.4826 * np.median(off)
    if keep.sum() >= MIN_FIT:
        coef = np.linalg.lstsq(design[keep], w[keep], rcond=None)[0]
    return float(abs(coef[0]) / np.sqrt(1.0 + coef[1] ** 2 + coef[2] ** 2))


def _edge(scan: Scan) -> np.ndarray:
    """(N,) bool: scan points on a rim or hole of its surface, or in no triangle (a stray point of a
    surface; every point of a cloud is in none)."""
    return scan.rims if scan.is_point_cloud else scan.rims | (np.bincount(scan.faces.ravel(), minlength=len(scan.vertices)) == 0)


def local_spacing(tree: cKDTree, points: np.ndarray) -> np.ndarray:
    """(K,) mm: the mean distance from the scan point nearest each of (K, 3) points to its NEAREST
    nearest neighbours (on an even cloud about 1.3 times the nearest-neighbour spacing)."""
    nearest = tree.query(points)[1]
    return tree.query(tree.data[nearest], k=NEAREST + 1)[0][:, 1:].mean(axis=1)


def data_reach(tree: cKDTree, points: np.ndarray, least_mm: float) -> np.ndarray:
    """(K,) mm: how near a scan point must lie to each of (K, 3) points for the scan to have data
    there: SPACINGS local spacings (`local_spacing`; a decimated mesh's vertices lie 10-20 mm apart
    where the face is flat), at least `least_mm`, at most NORMAL_REACH_MM."""
    return np.clip(SPACINGS * local_spacing(tree, points), least_mm, NORMAL_REACH_MM)


def off_skin(scan: Scan, tree: cKDTree, points: np.ndarray, reach: float | np.ndarray) -> np.ndarray:
    """(K,) distance (mm) of points from the scan: to the tangent plane at the nearest scan point
    when that is within `reach` (mm, one or (K,); a coarse mesh's vertices are far apart), else to
    the point."""
    dist, idx = tree.query(points)
    plane = np.abs(np.einsum("ij,ij->i", points - scan.vertices[idx], scan.normals[idx]))
    return np.where(dist <= reach, plane, dist)
