"""Does an aligned template lie on a face? The guard against confident alignments to non-faces.

Measures of the template's central face, carried by the similarity onto the scan:
- gap: distance from each template point to the scan surface (point-to-plane at the nearest scan
  point, capped at 10 mm; points with no scan point within 10 mm are uncovered);
- nose: how far the scan rises at its nose tip (the middle of its top layer near the template's
  tip, not one noise spike) above the scan 18 mm to either side of it (farther out, to 26 mm,
  where a hole leaves no data there) and above the deepest of the scan 20-40 mm below it (the
  mouth's line or the fold above the chin: the upper lip of some faces stands within 2-5 mm of
  a flat nose's tip), along the face's forward direction (a face: 10-30 mm and 8-25 mm; a
  sphere, a wall: a few mm to the sides; the edge of a box: a ridge, but nothing below); each
  height is where a camera in front of the face first meets the
  scan: the median first hit of a bundle of rays cast back along the forward direction within
  PROBE_MM across (a point cloud through a surface over its points facing that way). A column of
  points would also hold what lies behind the skin (a modelled head's nostril and lip insides
  read a nose tip as standing -4 to +3 mm above its sides), and one ray the noise's highest point.
  A nose lower than that but at least LOW_NOSE_MM (`FaceCheck.low_nose`: a flat nose, or a face
  the alignment pitched) passes only with a second look's agreement (`initial.py`);
- scale: the similarity's, template to scan. Adult faces differ from the template (an average
  adult's) by ~10 % in size; a face "found" at half or twice its size is another shape mistaken
  for one (a render's shading, a face seen at the wrong distance), or a scan in other units;
- depth (a capture only): the share of the central face's points whose pixel holds depth. It
  gates nothing, but a depth image riddled with holes meshes to too few triangles for the nose
  probes, and the measures then say so;
- turned (a capture only): the angle between the face's forward direction and the way from its nose
  tip to the camera. A camera sees a face from in front; a template facing away from it lies on the
  inside of a face shell seen from behind (a hollow mask), whose points are a face's.
"""

from dataclasses import dataclass, replace

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..crop import reachable
from ..errors import InputError
from ..landmarks.cloud import facing_surface
from ..rgbd import project
from ..scan import Scan
from ..template import Template
from ..similarity import Similarity
from ..tangents import plane_across
from ..thresholds import HEAD_MM, MIN_COVERAGE, MAX_MEDIAN_GAP_MM, MIN_RIDGE_MM, MIN_BELOW_MM, LOW_NOSE_MM, SCALE_RANGE, MAX_TURNED_DEG, SPARSE_DEPTH

NOSE_TIP, RIGHT_ALA, LEFT_ALA = 4, 129, 358
COVER_MM = 10.0
RIDGE_OFFSETS_MM = (18.0, 22.0, 26.0)  # probed in turn on each side: the first with scan data counts
BELOW_OFFSETS_MM = (20.0, 25.0, 30.0, 35.0, 40.0)  # probed all: the deepest with scan data counts (down to the lower lip)
PEAK_SEARCH_MM = 15.0
PEAK_LAYER_MM = 2.0  # the nose tip: the middle of the scan's top layer this thick
PROBE_MM = 4.0  # across each probe's bundle of rays
REACH_MM = 200.0  # the probing rays start this far in front of the face


@dataclass(frozen=True)
class FaceCheck:
    """coverage: fraction of central template points with the scan within 10 mm; median_gap_mm over
    those; ridge_mm, below_mm: how far the scan's nose tip stands out above the scan beside it and
    below it (a box's edge is a ridge but not a peak; NaN where the scan has no data there, which
    fails); scale: the template's size on the scan; turned_deg: the face's forward direction from the
    way to the camera, degrees; depth_fraction: the share of the central face's points whose pixel holds
    depth (both NaN for a mesh or point cloud)."""

    coverage: float
    median_gap_mm: float
    ridge_mm: float
    below_mm: float
    scale: float
    turned_deg: float = np.nan
    depth_fraction: float = np.nan

    @property
    def is_face(self) -> bool:
        return (
            self.coverage >= MIN_COVERAGE and self.median_gap_mm <= MAX_MEDIAN_GAP_MM
            and self.ridge_mm >= MIN_RIDGE_MM and self.below_mm >= MIN_BELOW_MM
            and SCALE_RANGE[0] <= self.scale <= SCALE_RANGE[1] and not self.turned_deg > MAX_TURNED_DEG
        )

    @property
    def low_nose(self) -> bool:
        """A face by every measure but its nose's, which rises LOW_NOSE_MM or more above its sides
        and below it but short of MIN_RIDGE_MM or MIN_BELOW_MM: a flat nose, or a bump that is no nose."""
        low = self.ridge_mm >= LOW_NOSE_MM and self.below_mm >= LOW_NOSE_MM  # False with NaN
        return low and not self.is_face and replace(self, ridge_mm=max(self.ridge_mm, MIN_RIDGE_MM), below_mm=max(self.below_mm, MIN_BELOW_MM)).is_face

    def describe(self) -> str:
        sides = f"{self.ridge_mm:.1f} mm above its sides (at least {MIN_RIDGE_MM})" if np.isfinite(self.ridge_mm) else "no scan beside it"
        below = (f"{self.below_mm:.1f} mm above the lip (at least {MIN_BELOW_MM})" if np.isfinite(self.below_mm)
                 else f"no scan {BELOW_OFFSETS_MM[0]:g}-{BELOW_OFFSETS_MM[-1]:g} mm below it")
        return (
            f"{100 * self.coverage:.0f} % of the central face covered (needs {100 * MIN_COVERAGE:.0f} %), median gap "
            f"{self.median_gap_mm:.1f} mm (at most {MAX_MEDIAN_GAP_MM}), nose tip {sides} and {below}, "
            f"template scaled x{self.scale:.2f} (an adult face: x{SCALE_RANGE[0]:g}-{SCALE_RANGE[1]:g})"
            + (f", turned {self.turned_deg:.0f} deg from the camera (at most {MAX_TURNED_DEG:g})" if np.isfinite(self.turned_deg) else "")
            + (f", depth at only {100 * self.depth_fraction:.0f} % of the face's pixels (the sensor's depth is riddled with holes)"
               if self.depth_fraction < SPARSE_DEPTH else "")
        )


def check_face(scan: Scan, template: Template, similarity: Similarity, central: np.ndarray) -> FaceCheck:
    """Measure how well the template's `central` vertex indices, aligned, lie on the scan."""
    tree = cKDTree(scan.vertices)
    pts = similarity.apply(template.vertices[central])
    dist, idx = tree.query(pts, workers=-1)
    covered = dist < COVER_MM
    plane = np.abs(np.einsum("ij,ij->i", pts - scan.vertices[idx], scan.normals[idx]))
    gap = float(np.median(plane[covered])) if covered.any() else np.inf
    return FaceCheck(float(covered.mean()), gap, *_nose(tree, scan, template, similarity), float(similarity.scale),
                     _turned(scan, template, similarity), _depth_fraction(scan, pts))


def _depth_fraction(scan: Scan, points: np.ndarray) -> float:
    """Share of the (K, 3) mm camera-frame `points` in a capture's view whose pixel holds depth; NaN
    with none in view, or for other scans."""
    if not scan.is_capture or scan.valid is None or scan.intrinsics is None:
        return np.nan
    ahead = points[points[:, 2] > 0]
    uv = np.round(project(ahead, scan.intrinsics)).astype(np.int64)
    h, w = scan.valid.shape
    seen = (uv >= 0).all(axis=1) & (uv[:, 0] < w) & (uv[:, 1] < h)
    return float(scan.valid[uv[seen, 1], uv[seen, 0]].mean()) if seen.any() else np.nan


def _turned(scan: Scan, template: Template, similarity: Similarity) -> float:
    """Degrees between the aligned face's forward direction and the way from its nose tip to a
    capture's camera (at the origin); NaN for other scans."""
    if not scan.is_capture:
        return np.nan
    tip = similarity.apply(template.vertices[[NOSE_TIP]])[0]
    cos = float(similarity.rotation[:, 2] @ (-tip / np.linalg.norm(tip)))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def nose_peak(tree: cKDTree, scan: Scan, near: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """The middle of the scan's top layer (along `forward`: within PEAK_LAYER_MM of its 98th
    percentile height) within PEAK_SEARCH_MM of `near`, sideways: the scan's own nose tip,
    wherever the alignment put the template's, and not a noise spike on it (mm)."""
    idx = tree.query_ball_point(near, r=PEAK_SEARCH_MM + 30.0)
    if not idx:
        return near
    pts = scan.vertices[idx]
    lateral = pts - near
    lateral -= np.outer(lateral @ forward, forward)
    pts = pts[np.linalg.norm(lateral, axis=1) < PEAK_SEARCH_MM]
    if not len(pts):
        return near
    height = pts @ forward
    return pts[height >= np.percentile(height, 98) - PEAK_LAYER_MM].mean(axis=0)


def _nose(tree: cKDTree, scan: Scan, template: Template, similarity: Similarity) -> tuple[float, float]:
    """How far the scan's nose tip (the peak near the aligned template's) stands out (mm, along the face's forward direction)
    above the scan to either side (those sides with data), each at the first of RIDGE_OFFSETS_MM
    with scan data, and above the deepest of the scan at BELOW_OFFSETS_MM (NaN: none has any), each height the
    first surface a camera in front of the face sees there (`first_surface`); the tip's, its top
    layer's (`nose_peak`: rays at a hole over the tip meet nothing)."""
    lm = template.vertices
    forward, up = similarity.rotation[:, 2], similarity.rotation[:, 1]
    side = similarity.rotation @ (lm[LEFT_ALA] - lm[RIGHT_ALA])
    side /= np.linalg.norm(side)
    tip = nose_peak(tree, scan, similarity.apply(lm[NOSE_TIP][None])[0], forward)
    beside = np.array([tip + s * offset * side for s in (-1.0, 1.0) for offset in RIDGE_OFFSETS_MM])
    below = tip - np.outer(BELOW_OFFSETS_MM, up)
    heights = first_surface(_facing(scan, forward), np.vstack([beside, below]), forward)
    sides = np.array([_first(row) for row in heights[: len(beside)].reshape(2, -1)])
    top = float(tip @ forward)
    rise = top - np.nanmean(sides) if np.isfinite(sides).any() else np.nan  # one side may be hidden
    return float(rise), float(top - _lowest(heights[len(beside):]))


def _facing(scan: Scan, forward: np.ndarray) -> trimesh.Trimesh:
    """The scan's surface as a camera looking back along unit `forward` sees it: its triangles, or a
    point cloud's surface over its points facing that way (`facing_surface`)."""
    seen = facing_surface(scan, forward) if scan.is_point_cloud else scan
    return trimesh.Trimesh(seen.vertices, seen.faces, process=False)


def first_surface(surface: trimesh.Trimesh, at: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """(K,) mm: the height along unit `forward` of the surface a camera in front sees at each of (K, 3)
    `at` points: the median first hit of 19 rays cast back along -forward within PROBE_MM
    across (from REACH_MM in front), NaN where fewer than half of them meet the surface."""
    if not len(surface.faces):
        return np.full(len(at), np.nan)
    disc = _disc() @ plane_across(forward)
    origins = (at[:, None, :] + disc[None] + REACH_MM * forward).reshape(-1, 3)
    probed = _along(surface, at, forward, 0.5 * PROBE_MM)
    hits, ray, _ = probed.ray.intersects_location(origins, np.tile(-forward, (len(origins), 1)), multiple_hits=False)
    height = np.full(len(origins), np.nan)
    height[ray] = hits @ forward
    height = height.reshape(len(at), -1)
    enough = np.isfinite(height).sum(axis=1) >= 0.5 * height.shape[1]
    out = np.full(len(at), np.nan)
    out[enough] = np.nanmedian(height[enough], axis=1)
    return out


def _along(surface: trimesh.Trimesh, at: np.ndarray, forward: np.ndarray, radius_mm: float) -> trimesh.Trimesh:
    """The triangles of `surface` a ray along unit `forward` passing within `radius_mm` across of one
    of (K, 3) `at` points can meet: those whose corners all lie that near across, give or take their
    longest edge (a point in a triangle lies no farther than that from each corner). A dense head's
    Embree scene is not built for a few probes."""
    vertices, faces, across = np.asarray(surface.vertices), np.asarray(surface.faces), plane_across(forward).T
    near = reachable(vertices, faces, cKDTree(at @ across).query(vertices @ across)[0], radius_mm)
    return trimesh.Trimesh(vertices, faces[near], process=False)


def _disc() -> np.ndarray:
    """(19, 2) mm offsets across the probe: its centre and rings of 6 and 12 out to PROBE_MM / 2."""
    rings = [(r, k) for r, n in ((0.25 * PROBE_MM, 6), (0.5 * PROBE_MM, 12)) for k in np.arange(n) * 2 * np.pi / n]
    return np.array([[0.0, 0.0]] + [[r * np.cos(k), r * np.sin(k)] for r, k in rings])


def _lowest(heights: np.ndarray) -> float:
    """The least finite of the heights (mm), NaN if none."""
    return float(np.nanmin(heights)) if np.isfinite(heights).any() else np.nan


def _first(heights) -> float:
    """The first finite of the heights (mm), NaN if none."""
    return next((h for h in heights if np.isfinite(h)), np.nan)


def scale_question(scan: Scan) -> str:
    """What to ask of a scan on which the face found is not an adult's size: its depth scale and
    intrinsics (a capture, a sweep, a RealSense recording: millimetres from a depth scale), or its
    units (a mesh or a point cloud), saying how they were decided."""
    if scan.is_capture or "from depth_scale" in scan.units_note:
        return "are its depth scale and intrinsics this camera's?"
    return f"are its units right? {scan.units_note or 'units: ' + scan.units}; state them with --units"


def require_face(check: FaceCheck, how: str, question: str = "are its units right? state them with --units",
                 across_mm: float = np.nan) -> None:
    """Raise a clear error when the alignment does not lie on a face, asking `question`
    (`scale_question`) where the face found is not an adult's size; `across_mm`: a mesh's or cloud's
    robust extent, mm: a scene or a body is to be cropped to the head."""
    if not check.is_face:
        units = "" if SCALE_RANGE[0] <= check.scale <= SCALE_RANGE[1] else f" (or {question})"
        crop = f"; the scan is {across_mm:.0f} mm across, more than a head ({HEAD_MM:.0f}): crop it to the head" if across_mm > HEAD_MM else ""
        raise InputError(f"no face found ({how}): {check.describe()}{crop}; is this a face scan, facing the sensor{units}?")
