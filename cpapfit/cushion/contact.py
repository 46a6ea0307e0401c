"""The mask's contact region carried onto the patient: the closed seal curve and its band.

On the template, the region's centre curve (an edge path) is resampled evenly, smoothed, and
stored as barycentric points on template triangles. Through the registration (same triangles,
warped vertices) they land on the patient's face; each is then moved along the skin normal onto
the scan itself where the scan has data within PROJECT_MM along that normal (a point over a hole
stays: the seal must not be dragged to the hole's rim), so the cushion touches the real face
rather than the template's approximation of it. For a point cloud, "along the normal" means
within TANGENT_MM of the normal line, or within 3/4 of the cloud's local spacing there where that
is more, up to twice TANGENT_MM (`gap.local_spacing`, about 1.2 times the spacing inside a cloud,
more at its rims: through a cloud 1.9 mm apart a line misses every point within 1 mm on a third of
the seal). "Onto the scan" means onto the skin the scan measures: a
quadric height field fitted by weighted least squares to the scan points around the hit (Gaussian
width SKIN_WIDTH_MM, widened to take in SKIN_NEIGHBOURS points where the scan is coarse), so that
the seal follows the face and not the sensor's noise or depth steps (a local moving-least-squares
projection). On a sparse mesh, too coarse to fit, the crossing itself is the skin. Each point's
offset from the template then becomes the median over OUTLIER_SAMPLES scanned neighbours along the
seal, so that one stray fit or crossing (a flying pixel, a depth step, a normal line through a
nostril's opening: a seal curve turning back on itself by 167 degrees, on a head mesh with 2 mm
facets) cannot kink the seal; an offset over OFFSET_MM (the registration's own pair gate: the
registered face lies on the scan it was paired with to a fraction of that) is another surface, and
the point counts as over no data (a cloud of a head with its nostrils' insides, 1.9 mm apart: three
neighbouring seal points 7-9 mm inside the nose, which the running median keeps). A head modelled with its nostrils' insides has a second layer of skin a few mm behind the
ala: only triangles and points facing the way the skin does count, and a skin fit that would leave a
point over LAYER_MM farther from the scan's nearest point than it began (through both layers: a seal
2-8 mm inside the nose) gives way to the crossing itself. Where the scan has no data the seal keeps
the registered template's guess, but not with a step at the data's edge: the offset the last scanned points took (scan minus template, along the
normal) carries on into the gap and fades away over ~FADE_MM of seal; across a short hole it runs
from one edge's offset to the other's.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import trimesh
from scipy.ndimage import gaussian_filter1d, median_filter
from scipy.spatial import cKDTree

from ..align.nonrigid import NonrigidParams
from ..crop import reachable
from ..evaluation.gap import local_spacing
from ..frozen import freeze_arrays
from ..template import Template, load_template

SAMPLES = 128  # points around the seal
SMOOTH_SAMPLES = 2.0  # Gaussian smoothing of the edge path, in samples
PROJECT_MM = 10.0  # no scan within this along the skin normal: no data there, keep the registered point
TANGENT_MM = 1.0  # point clouds: a closest scan point farther sideways than this (or 3/4 of the local spacing, up to twice this) is a hole's rim
OFFSET_MM = NonrigidParams().max_distance_mm  # a seal point this far from the registered face along its normal has met another surface
SKIN_WIDTH_MM = 2.0  # Gaussian width of the local skin fit; scan points within twice this take part
FADE_MM = 10.0  # arc length over which the scan's offset fades into a gap in the data
SKIN_MIN_POINTS = 12  # fewer scan points than this around a seal point (a sparse mesh): keep its closest point
SKIN_NEIGHBOURS = 60  # the skin fit reaches out to this many scan points (a coarse, noisy capture: wider)
OUTLIER_SAMPLES = 5  # the seal's offsets onto the scan: a running median over this many scanned points
LAYER_MM = 1.0  # a skin fit leaving a point this much farther from the scan's nearest point has reached another layer


@dataclass(frozen=True)
class Contact:
    """The seal on the patient (mm, scan frame).

    curve: (K, 3) closed seal curve, ordered around the loop (last joins first).
    normals: (K, 3) unit skin normals at the curve points (out of the face).
    on_scan: (K,) bool: the point was moved onto the scan (False: no scan data near it).
    band: (B, 3) the contact band's template vertices on the patient (registered positions).
    """

    mask: str
    curve: np.ndarray
    normals: np.ndarray
    on_scan: np.ndarray
    band: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)

    def normals_at(self, points: np.ndarray) -> np.ndarray:
        """(K, 3) the skin normals at the seal curve's points nearest (K, 3) `points` (mm)."""
        return self.normals[cKDTree(self.curve).query(points)[1]]


def closed_resample(points: np.ndarray, n: int, values: np.ndarray | None = None) -> np.ndarray:
    """n stations evenly spaced by arc length along a closed polyline (K, 3): the (n, 3) points
    there, or, given `values` (K, ...) carried by the points, those values interpolated there."""
    loop = np.vstack([points, points[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(loop, axis=0), axis=1))])
    t = np.linspace(0.0, s[-1], n, endpoint=False)
    data = loop if values is None else np.concatenate([values, values[:1]]).reshape(len(loop), -1)
    out = np.stack([np.interp(t, s, column) for column in data.T], axis=1)
    return out.reshape((n,) + (loop.shape[1:] if values is None else np.shape(values)[1:]))


@lru_cache(maxsize=4)
def template_curve(mask: str) -> tuple[np.ndarray, np.ndarray]:
    """(triangles (K,), barycentric (K, 3)) of the smoothed seal curve on the template."""
    template = load_template()
    pts = closed_resample(template.vertices[template.regions[mask].curve], SAMPLES)
    pts = gaussian_filter1d(pts, SMOOTH_SAMPLES, axis=0, mode="wrap")
    mesh = template.mesh()
    closest, _, tri = trimesh.proximity.closest_point(mesh, pts)
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[tri], closest)
    return tri, bary


def transfer_contact(template: Template, warped: np.ndarray, surface: trimesh.Trimesh | trimesh.PointCloud, mask: str) -> Contact:
    """The seal curve and band of `mask` on the patient, from the warped template (n, 3) mm, moved
    onto the scan's surface (`scan_surface`) where it is near."""
    tri, bary = template_curve(mask)
    corners = warped[template.faces[tri]]  # (K, 3, 3)
    carried = np.einsum("kj,kjc->kc", bary, corners)
    normals = np.einsum("kj,kjc->kc", bary, trimesh.Trimesh(warped, template.faces, process=False).vertex_normals[template.faces[tri]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    moved, on_scan = onto_scan(carried, normals, surface)
    fade = faded_offsets(carried, np.einsum("ij,ij->i", moved - carried, normals), on_scan)
    curve = np.where(on_scan[:, None], moved, carried + fade[:, None] * normals)
    return Contact(mask, curve, normals, on_scan, warped[template.regions[mask].band])


def onto_scan(points: np.ndarray, normals: np.ndarray, surface: trimesh.Trimesh | trimesh.PointCloud) -> tuple[np.ndarray, np.ndarray]:
    """The (K, 3) points moved along their (K, 3) unit normals onto the skin the scan measures
    (`scan_surface`), and (K,) which moved: those with scan data within PROJECT_MM along the normal
    whose skin there lies at most OFFSET_MM from them."""
    if isinstance(surface, trimesh.PointCloud):
        hit, near = _closest_along(points, normals, surface.kdtree)
        sample, facing = surface.vertices, None
        nearest = surface.vertices[surface.kdtree.query(points)[1]]
    else:
        nearest, tri = _closest_on(surface, points)
        winding = np.sign(np.einsum("ij,ij->i", np.asarray(surface.face_normals)[tri], normals).sum()) or 1.0
        hit, near = _hit_along(points, normals, surface, winding)
        used = np.unique(surface.faces)
        sample, facing = surface.vertices[used], winding * np.asarray(surface.vertex_normals)[used]
    skin = local_skin(hit, normals, np.asarray(sample), facing)
    offset = np.einsum("ij,ij->i", skin - points, normals)
    astray = np.linalg.norm(skin - nearest, axis=1) > np.linalg.norm(points - nearest, axis=1) + LAYER_MM
    offset[astray] = np.einsum("ij,ij->i", hit - points, normals)[astray]  # the skin fit reached another layer: the crossing
    near &= np.abs(offset) <= OFFSET_MM
    if near.any():
        offset[near] = median_filter(offset[near], size=min(OUTLIER_SAMPLES, int(near.sum())), mode="wrap")
    return np.where(near[:, None], points + offset[:, None] * normals, points), near


def _closest_on(surface: trimesh.Trimesh, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((K, 3) mm the surface's point nearest each of (K, 3) points, (K,) a triangle holding it), as
    `trimesh.proximity.closest_point` finds them (the same points; on an edge or corner shared by
    triangles, any of them), among only the triangles that can hold one (`crop.reachable`): those
    whose corners all lie within R of some point, give or take their longest edge, R the farthest
    any point lies from its nearest triangle corner. The surface lives through the design, and a
    dense scan's r-tree of every triangle would live with it."""
    vertices, faces = np.asarray(surface.vertices), np.asarray(surface.faces)
    corners = vertices[np.unique(faces)]  # a vertex in no triangle holds no closest point
    near = reachable(vertices, faces, cKDTree(points).query(vertices)[0], cKDTree(corners).query(points)[0].max())
    nearest, _, tri = trimesh.proximity.closest_point(trimesh.Trimesh(vertices, faces[near], process=False), points)
    return nearest, near[tri]


def faded_offsets(loop: np.ndarray, offset: np.ndarray, known: np.ndarray) -> np.ndarray:
    """(K,) offsets (mm) along a closed (K, 3) loop: `offset` where `known` (K,) bool; in a gap, at
    arc lengths a and b from its two edges, the edges' offsets blended linearly and faded by
    exp(-a b / ((a + b) FADE_MM)): near an edge exp(-a / FADE_MM), across a short hole nearly a
    straight ramp, deep in a long gap zero (the template's guess)."""
    if known.all() or not known.any():
        return np.where(known, offset, 0.0)
    step = np.linalg.norm(np.roll(loop, -1, axis=0) - loop, axis=1)
    s = np.concatenate([[0.0], np.cumsum(step)[:-1]])
    length = step.sum()
    at = np.flatnonzero(known)
    before = at[np.searchsorted(at, np.arange(len(loop)), side="right") - 1]  # index -1 wraps to the last known
    after = at[np.searchsorted(at, np.arange(len(loop)), side="left") % len(at)]
    a, b = (s - s[before]) % length, (s[after] - s) % length
    gap = np.maximum(a + b, 1e-12)
    out = (b * offset[before] + a * offset[after]) / gap * np.exp(-a * b / (gap * FADE_MM))
    return np.where(known, offset, out)


def _hit_along(points: np.ndarray, normals: np.ndarray, mesh: trimesh.Trimesh, winding: float) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) the mesh's crossing of each point's normal line nearest the point, and (K,) whether
    there is one within PROJECT_MM (where not, the point itself). Only triangles facing the way the
    skin does count (their normals times `winding`, +-1: the mesh's, out of the face): the inside of
    a modelled nostril lies a few mm behind the ala, and a seal pulled onto it dived 4 mm into the nose."""
    origins = points - PROJECT_MM * normals
    where, ray, tri = mesh.ray.intersects_location(origins, normals, multiple_hits=True)
    miss = np.abs(np.einsum("ij,ij->i", where - origins[ray], normals[ray]) - PROJECT_MM)
    facing = winding * np.einsum("ij,ij->i", np.asarray(mesh.face_normals)[tri], normals[ray]) > 0.0
    keep = (miss <= PROJECT_MM) & facing
    order = np.lexsort((miss[keep], ray[keep]))
    ray, where = ray[keep][order], where[keep][order]
    first = np.unique(ray, return_index=True)[1]
    hit, near = points.copy(), np.zeros(len(points), dtype=bool)
    hit[ray[first]], near[ray[first]] = where[first], True
    return hit, near


def _closest_along(points: np.ndarray, normals: np.ndarray, cloud: cKDTree) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) where each point's normal line passes the cloud: level with the cloud point nearest the
    point along the line among those within TANGENT_MM of it and PROJECT_MM of the point (a ray cast
    at a cloud; `local_skin` then puts it on the skin there; 3/4 of the cloud's local spacing there
    instead of TANGENT_MM where it is more, up to twice TANGENT_MM), and (K,) whether there is one (where not, the point itself).
    `cloud`: the cloud's k-d tree (the surface's own, built once)."""
    hit, near = points.copy(), np.zeros(len(points), dtype=bool)
    reach = np.clip(0.75 * local_spacing(cloud, points), TANGENT_MM, 2.0 * TANGENT_MM)
    for k, around in enumerate(cloud.query_ball_point(points, PROJECT_MM)):  # each list ascending
        offset = cloud.data[np.asarray(around, dtype=np.int64)] - points[k]
        along = offset @ normals[k]
        sideways = np.linalg.norm(offset - along[:, None] * normals[k], axis=1)
        on_line = np.flatnonzero(sideways <= reach[k])
        if len(on_line):
            nearest = on_line[np.argmin(np.abs(along[on_line]))]
            hit[k], near[k] = points[k] + along[nearest] * normals[k], True
    return hit, near


def local_skin(points: np.ndarray, normals: np.ndarray, sample: np.ndarray, facing: np.ndarray | None = None) -> np.ndarray:
    """(K, 3) points moved along their (K, 3) unit normals onto a quadric height field fitted to the
    (S, 3) scan points around each: its SKIN_NEIGHBOURS nearest, Gaussian weights of width
    SKIN_WIDTH_MM or half the farthest one's distance if more. Given the
    sample's (S, 3) unit normals `facing` (out of the face), only the points facing the side each
    point's normal does take part: a modelled nostril's inside lies a few mm behind the ala, and a fit
    through both layers put a seal 3.6 mm off the skin. A point with fewer than SKIN_MIN_POINTS such
    scan points within 2 SKIN_WIDTH_MM across the skin (a sparse mesh) stays. mm."""
    out = points.copy()
    nearest = cKDTree(sample).query(points, k=min(SKIN_NEIGHBOURS, len(sample)))[1].reshape(len(points), -1)
    offsets = sample[nearest] - points[:, None]  # (K, SKIN_NEIGHBOURS, 3)
    height = np.einsum("knc,kc->kn", offsets, normals)
    distance_sq = np.sum(offsets**2, axis=2)
    across = np.sqrt(np.maximum(distance_sq - height**2, 0.0))
    same = np.ones(nearest.shape, dtype=bool) if facing is None else np.einsum("knc,kc->kn", facing[nearest], normals) > 0.0
    fitted = np.sum(same & (across <= 2.0 * SKIN_WIDTH_MM), axis=1) >= SKIN_MIN_POINTS
    widths = np.maximum(SKIN_WIDTH_MM, np.sqrt(distance_sq.max(axis=1)) / 2.0)
    for k in np.flatnonzero(fitted):
        out[k] += _height(offsets[k][same[k]], normals[k], widths[k]) * normals[k]
    return out


def _height(offsets: np.ndarray, normal: np.ndarray, width: float) -> float:
    """Height (mm, along the unit normal) at the origin of the quadric h(u, v) fitted to (S, 3)
    offsets with Gaussian weights of `width` (mm)."""
    side = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    side /= np.linalg.norm(side)
    u, v, h = offsets @ side, offsets @ np.cross(normal, side), offsets @ normal
    root_w = np.exp(-(u**2 + v**2) / (4.0 * width**2))
    design = np.column_stack([np.ones_like(u), u, v, u * u, u * v, v * v]) * root_w[:, None]
    return float(np.linalg.lstsq(design, h * root_w, rcond=None)[0][0])
