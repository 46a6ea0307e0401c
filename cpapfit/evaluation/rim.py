"""Where a cushion meets the face: its contact line, found from the cushion's own mesh.

The cushion (any triangle mesh in the scan frame: the designed solid, an STL from elsewhere, a
stock cushion) is refined to 0.7 mm edges (REFINE_MM); every vertex of its wall near the face end (at most
RIM_BAND_MM up the axis from the lowest in its direction) looks down the mask axis for the skin: first
those at most SURE_MM up and every VOTE_EVERY-th of the band (whose hits vote on which side of the
scan is out), then the higher ones that could still touch first by the skin's ceiling over them
(`ceiling.py`: the highest a triangle they could meet stands), which finds the same rim.
Around the axis, in SECTORS equal angles, the vertex with the least clearance is the rim's
contact point in that direction: the first part of the cushion the skin meets when the mask is
pushed on. How far inside the skin it is: its distance to the nearest skin, over the |cos| of
that skin's normal (`_nearest_skin`; along the axis, curved skin misjudges it); under a sheet the
scan sees from one side only, its height over that skin. Evaluating the
written mesh (not the design's internal curve) means `design` and `evaluate` measure the same
thing. A membrane (`membrane.py`: the mesh thinner than MEMBRANE_MAX_MM) is not the rim: it is
measured, per sector, for the seal it adds.
"""

from dataclasses import dataclass
from itertools import chain

import numpy as np
import trimesh
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from ..errors import InputError
from ..frozen import freeze_arrays, read_only
from ..kept import Kept
from ..scan import Scan
from ..tangents import across
from .ceiling import ceilings
from .membrane import MEMBRANE_MAX_MM, face_thickness_mm, rim_membrane, vertex_thickness_mm
from ..thresholds import MIN_COVERED
from .mechanics import COS_MIN

SECTORS = 256
REFINE_MM = 0.7  # longest cushion edge after refinement (at 1.0 mm a cushion moved 0.1 mm read its force 9 % apart: bench/rim_stability.py)
REACH_MM = 60.0  # rays look this far up (rims pressed into the skin) and down the axis for the skin
CLOUD_RADIUS_MM = 2.0  # a ray "hits" a point cloud's points this close to it
CLOUD_LAYER_MM = 3.0  # deeper than this below the topmost of them: another surface
TIE_MM = 0.1  # clearances this close count as equal when choosing a sector's rim point
LENGTH_SECTORS = 3.0  # the rim's length is read along its points smoothed over this many sectors (Gaussian)
FACE_MM = 4.0  # scanned skin farther than this behind the registered face along the ray: a hole in the scan
PROBE_MM = 1.0  # a mesh's skin under a rim point: the median height under the point and PROBE_RAYS around it
PROBE_RAYS = 6
RIM_BAND_MM = 15.0  # a rim point is a wall vertex at most this far up the axis from its sector's lowest
SURE_MM = 1.0  # rays first from the wall this far up from its sector's lowest; higher, only where they could touch first
VOTE_EVERY = 16  # and from every this many-th of the band: their hits alone vote on which side of the skin is out
MEMBRANE_SPREAD = 12  # a rim point's section takes in the membrane hanging from the rim this many sectors either side
NORMAL_MM = 2.5  # the skin's normal under a rim point: the scan's, over this radius (half the 5 mm flange)
NORMAL_POINTS = 5  # a point cloud's normal needs this many points within NORMAL_MM
CANDIDATES = 8  # the nearest skin on a mesh: on the triangles around this many nearest vertices
STRAY_MM = 1.0  # the nearest skin this far under the plane of the scan around it is a flap curled under, not skin
_REFINED = Kept(2)  # the last cushions `refined`


@dataclass(frozen=True)
class RimContact:
    """A cushion's contact line over the face, one point per sector around the mask axis.

    points: (K, 3) mm rim points on the cushion; skin: (K, 3) mm skin below each, along -axis;
    clearance: (K,) mm the rim travels along the axis to touch the skin (negative: rim inside the
    skin, where its depth is its distance to the nearest skin over cos, `_nearest_skin`, which also
    reads points under a sheet seen from one side only as in the air; NaN where no skin was found
    along the axis, i.e. not covered); cos: (K,) |cos| of the angle between the axis and the normal
    of the skin the clearance is measured to (the scan's, averaged over NORMAL_MM; the registered
    template's where the scan has too little there); ds: (K,) mm of seal length each point stands
    for (`seal_lengths`); uv: (K, 2) mm in-plane position about the rim's centre (side, up); sealed_area_mm2: area
    inside the rim, across the axis;
    membrane_mm, membrane_thickness_mm: (K,) width and thickness of the membrane at each rim point
    (0: none)."""

    points: np.ndarray
    skin: np.ndarray
    clearance: np.ndarray
    cos: np.ndarray
    ds: np.ndarray
    uv: np.ndarray
    axis: np.ndarray
    sealed_area_mm2: float
    membrane_mm: np.ndarray
    membrane_thickness_mm: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)

    @property
    def covered(self) -> np.ndarray:
        """(K,) bool: skin found under the rim point."""
        return np.isfinite(self.clearance)


def in_plane(axis: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(2, 3) unit (side, up) directions across the unit mask `axis`."""
    up = up - (up @ axis) * axis
    up = up / np.linalg.norm(up)
    return np.stack([np.cross(up, axis), up])


@dataclass(frozen=True)
class RimZone:
    """The vertices of a refined cushion (mm, scan frame) its contact line is found among, for one
    mask axis: its wall near the face end (`wall` (W, 3) mm), its membrane (`thin` (M, 3) mm,
    `thin_mm` (M,) mm thick) and the mean of all its vertices (`centre` (3,) mm), about which the
    sectors turn. Moved across the axis, or turned about it by as much as it was made for
    (`rim_zone`), it is the zone of the cushion so moved."""

    wall: np.ndarray
    thin: np.ndarray
    thin_mm: np.ndarray
    centre: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)

    def moved(self, transform: np.ndarray) -> "RimZone":
        """The zone of the cushion moved by a rigid (4, 4) `transform`."""
        wall, thin, centre = (trimesh.transform_points(np.atleast_2d(a), transform) for a in (self.wall, self.thin, self.centre))
        return RimZone(wall, thin, self.thin_mm, centre[0])


def rim_zone(cushion: trimesh.Trimesh, axis: np.ndarray, up: np.ndarray, thickness: np.ndarray | None = None,
             sectors: int = SECTORS, turn_deg: float = 0.0) -> RimZone:
    """The `RimZone` of a `cushion` mesh about the unit mask `axis` (`up`: the head's up direction):
    each wall vertex at most RIM_BAND_MM up the axis from the highest of the lowest wall vertices of
    the sectors within `turn_deg` of its own, so that every vertex `rim_in` could choose stays in it
    when the cushion is turned about the axis by up to `turn_deg` degrees. `thickness`: given, the
    cushion is already `refined` and this is its (V,) thickness mm."""
    fine, thickness = refined(cushion) if thickness is None else (cushion, thickness)
    vertices = np.asarray(fine.vertices)
    centre = vertices.mean(axis=0)
    sector = _sector((vertices - centre) @ in_plane(axis, up).T, sectors)
    wall = thickness > MEMBRANE_MAX_MM
    low = _lowest(vertices @ axis, sector, wall, sectors)
    turn = int(np.ceil(abs(turn_deg) / 360.0 * sectors))
    reach = np.max([np.roll(low, k) for k in range(-turn, turn + 1)], axis=0)
    keep = wall & (vertices @ axis - reach[sector] <= RIM_BAND_MM)
    thin = thickness <= MEMBRANE_MAX_MM
    return RimZone(vertices[keep], vertices[thin], thickness[thin], centre)


def find_rim(
    cushion: trimesh.Trimesh, scan: trimesh.Trimesh | trimesh.PointCloud, face_mesh: trimesh.Trimesh, axis: np.ndarray,
    up: np.ndarray, sectors: int = SECTORS, thickness: np.ndarray | None = None,
) -> RimContact:
    """The contact line of a `cushion` mesh over a `scan` surface or point cloud, mm, scan frame
    (`rim_in` its `rim_zone`); `thickness`: given, the cushion is already `refined` and this is its
    (V,) thickness mm."""
    return rim_in(rim_zone(cushion, axis, up, thickness, sectors), scan, face_mesh, axis, up, sectors)


def rim_in(
    zone: RimZone, scan: trimesh.Trimesh | trimesh.PointCloud, face_mesh: trimesh.Trimesh, axis: np.ndarray,
    up: np.ndarray, sectors: int = SECTORS,
) -> RimContact:
    """The contact line of a cushion (its `RimZone`) over a `scan` surface or point cloud, mm, scan
    frame. Each sector's rim point is the wall vertex that first touches the skin along the axis:
    the scanned skin where the scan is a mesh (`_touch_heights`), `face_mesh` (the registered
    template: the whole face, no holes) over its holes and under a point cloud. Its clearance is
    measured against the scan; where the scan's skin is missing or lies more than
    FACE_MM behind the face (a ray through a hole), the point is not covered (scan standing in front
    of the face counts: the cushion would press on it, and so does a point inside the scanned skin,
    `_through_hole`); InputError if less than MIN_COVERED of the
    rim is. `axis`: the unit mask axis (out of the face); `up`: the head's up direction."""
    vertices = zone.wall
    plane = in_plane(axis, up)
    uv = (vertices - zone.centre) @ plane.T
    sector = _sector(uv, sectors)
    along = vertices @ axis
    low = _lowest(along, sector, np.ones(len(vertices), dtype=bool), sectors)[sector]
    near = along - low <= RIM_BAND_MM
    on_face, face_cos, height = _band_heights(vertices, near, along, low, sector, sectors, uv + zone.centre @ plane.T, scan,
                                              face_mesh, axis, plane)
    first = _first_in_sector(np.flatnonzero(near), sector, _level(height), np.linalg.norm(uv, axis=1), sectors)
    if len(first) < sectors or not np.isfinite(height[first]).all():
        raise InputError("the cushion does not run all the way round the mask axis over the face or the scan")
    pts = vertices[first]
    clearance, skin = _skin_below(pts, scan, axis)
    clearance[_through_hole(clearance, on_face[first])] = np.nan
    covered = np.isfinite(clearance).mean()
    if covered < MIN_COVERED:
        raise InputError(f"only {100 * covered:.0f} % of the cushion's rim lies over scanned skin "
                         f"(at least {100 * MIN_COVERED:.0f} % needed): {_why_uncovered(scan)}")
    rim_uv = (pts - pts.mean(axis=0)) @ plane.T
    membrane = rim_membrane(zone.thin, zone.thin_mm, pts, MEMBRANE_SPREAD)
    cos = np.abs(_skin_planes(skin, scan)[0] @ axis)
    cos = np.where(np.isfinite(cos), cos, np.abs(face_cos[first]))
    clearance, cos = _nearest_skin(pts, clearance, cos, scan, axis)
    return RimContact(pts, skin, clearance, cos, seal_lengths(pts), rim_uv, axis, _area(rim_uv), *membrane)


def _first_in_sector(candidates: np.ndarray, sector: np.ndarray, level: np.ndarray, radius: np.ndarray, sectors: int) -> np.ndarray:
    """The first to touch in each sector that has any of the (C,) increasing vertex indices
    `candidates`, in sector order: the least `level` (V,), then the least `radius` (V,) mm, then the
    least index (`sector` (V,) each vertex's)."""
    for key in (level, radius):
        least = np.full(sectors, np.inf)
        np.minimum.at(least, sector[candidates], key[candidates])
        candidates = candidates[key[candidates] == least[sector[candidates]]]
    return candidates[np.unique(sector[candidates], return_index=True)[1]]


def _band_heights(vertices: np.ndarray, near: np.ndarray, along: np.ndarray, low: np.ndarray, sector: np.ndarray, sectors: int, flat: np.ndarray,
                  scan: trimesh.Trimesh | trimesh.PointCloud, face_mesh: trimesh.Trimesh, axis: np.ndarray,
                  plane: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(on_face, face_cos, height) (V,) of the cushion's (V, 3) wall `vertices` (`Heights`), which
    order the `near` (V,) bool as casting from every one would (NaN where no ray was cast): first
    from those at most SURE_MM up the axis (`along` (V,) mm) from their sector's lowest (`low`
    (V,) mm, `sector` (V,) of `sectors`) and every VOTE_EVERY-th of the band, whose hits alone vote
    on which side of a surface is out (a sample of the band's, which all voted), then from the higher ones whose
    height over the skin's ceiling (`ceilings`, at `flat` (V, 2) mm across the axis, `plane` (2, 3))
    could tie or beat their sector's first touch."""
    higher = near & (along - low > SURE_MM)
    voters = near & ((np.cumsum(near) - 1) % VOTE_EVERY == 0)
    first = (near & ~higher) | voters
    heights = _touch_heights(vertices, first, scan, face_mesh, axis, voters=voters)
    best = np.full(sectors, np.inf)
    np.minimum.at(best, sector, _level(heights.height))
    bound = along - ceilings(flat, [face_mesh] + ([scan] if isinstance(scan, trimesh.Trimesh) else []), axis, plane)
    rest = higher & ~first & (np.round(bound / TIE_MM) <= best[sector])
    return heights.joined(_touch_heights(vertices, rest, scan, face_mesh, axis, heights.out))


@dataclass(frozen=True)
class Heights:
    """Heights along the mask axis of the `cast` (V,) bool of a cushion's V wall vertices, NaN at the
    others: over the registered face (`on_face` (V,) mm, its normal . axis `face_cos` (V,)) and over
    the skin (`height` (V,) mm, negative inside it: what orders them by first touch); `out` (mesh,
    scan) the sides the surfaces' hits face (`_height_over`)."""

    cast: np.ndarray
    on_face: np.ndarray
    face_cos: np.ndarray
    height: np.ndarray
    out: tuple

    def joined(self, other: "Heights") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(on_face, face_cos, height) of these vertices and `other`'s."""
        return tuple(np.where(other.cast, getattr(other, name), getattr(self, name)) for name in ("on_face", "face_cos", "height"))


def _touch_heights(vertices: np.ndarray, cast: np.ndarray, scan: trimesh.Trimesh | trimesh.PointCloud, face_mesh: trimesh.Trimesh,
                   axis: np.ndarray, out: tuple = (None, None), voters: np.ndarray | None = None) -> Heights:
    """The `Heights` of the `cast` (V,) bool of the cushion's (V, 3) wall `vertices` along the unit
    `axis`: over a mesh scan, its height over the scanned skin (one ray: the rim point's clearance is
    then read as the median of a few, `skin_under`; skin past the registered face's edge, within
    REACH_MM, is skin), unless that ray meets no skin or goes through a hole (`_through_hole`); else,
    and over a point cloud, its height over the registered face `face_mesh`; `out`: the sides the
    hits face where already found, else as the hits of the `voters` (V,) bool (all cast, where given) face."""
    points, axes = vertices[cast], np.broadcast_to(axis, (int(cast.sum()), 3))
    voting = None if voters is None else voters[cast]
    on_face, face_cos = np.full(len(vertices), np.nan), np.zeros(len(vertices))
    on_face[cast], face_cos[cast], face_out = _height_over(points, face_mesh, axes, REACH_MM, out[0], voting)
    if not isinstance(scan, trimesh.Trimesh):
        return Heights(cast, on_face, face_cos, on_face, (face_out, None))
    on_scan = np.full(len(vertices), np.nan)
    on_scan[cast], _, scan_out = _height_over(points, scan, axes, REACH_MM, out[1], voting)
    height = np.where(np.isfinite(on_scan) & ~_through_hole(on_scan, on_face), on_scan, on_face)
    return Heights(cast, on_face, face_cos, height, (face_out, scan_out))


def _level(height: np.ndarray) -> np.ndarray:
    """(V,) heights (mm, NaN: no skin) in steps of TIE_MM, the order of first touch: clearances
    this close count as equal (a flange flat on the skin: the inner edge is the rim)."""
    return np.round(np.where(np.isfinite(height), height, np.inf) / TIE_MM)


def _through_hole(on_scan: np.ndarray, on_face: np.ndarray) -> np.ndarray:
    """(K,) bool: points whose height over the scanned skin `on_scan` (K,) mm lies more than FACE_MM
    past their height over the registered face `on_face` (K,) mm, a ray through a hole meeting what
    lies behind it; a point the registered face reads inside it counts as on its skin (height 0),
    however deep in an overhang of the face it reads (the wing of the nose beside its crease), so a
    point inside the scanned skin is never over a hole. NaN (no skin found) is not a hole here."""
    return np.nan_to_num(on_scan - np.maximum(on_face, 0.0), nan=-np.inf) > FACE_MM


def _sector(uv: np.ndarray, sectors: int) -> np.ndarray:
    """(V,) the sector (of `sectors` equal angles about the axis) of each (V, 2) mm position across it from the centre."""
    return np.minimum((np.arctan2(uv[:, 1], uv[:, 0]) + np.pi) / (2 * np.pi) * sectors, sectors - 1).astype(int)


def _lowest(height: np.ndarray, sector: np.ndarray, wall: np.ndarray, sectors: int) -> np.ndarray:
    """(sectors,) the least `height` (V,) mm of the `wall` vertices in each sector (inf where none)."""
    low = np.full(sectors, np.inf)
    np.minimum.at(low, sector[wall], height[wall])
    return low


def refined(cushion: trimesh.Trimesh) -> tuple[trimesh.Trimesh, np.ndarray]:
    """(the cushion mesh with no edge longer than REFINE_MM (a refined mesh is its own refinement),
    its (V,) thickness mm: at a closed cushion's own vertices `vertex_thickness_mm` of its faces'
    `face_thickness_mm`; at a vertex made by refining, the least over the faces it lies on of the
    most of their source face's corners. A face across a sheet's end (a flap's free edge, whose
    own ray runs along the flap) is as thin as its corners, which lie on the flap's two sides;
    inf on an open sheet). The last two cushions' are kept: a design evaluates its cushion awake
    and then presses the same cushion asleep (shared: not to be changed)."""
    return _REFINED.get((np.asarray(cushion.vertices).tobytes(), np.asarray(cushion.faces).tobytes()), lambda: _refined(cushion))


def _refined(cushion: trimesh.Trimesh) -> tuple[trimesh.Trimesh, np.ndarray]:
    """`refined`, made (a mesh of its own, its thickness read-only)."""
    face = face_thickness_mm(cushion) if cushion.is_watertight else np.full(len(cushion.faces), np.inf)
    corner = vertex_thickness_mm(cushion, face)
    points = cushion.vertices[cushion.faces]
    if np.linalg.norm(points - np.roll(points, 1, axis=1), axis=2).max() <= REFINE_MM:
        return trimesh.Trimesh(np.array(cushion.vertices), np.array(cushion.faces), process=False), read_only(corner)
    vertices, faces, source = trimesh.remesh.subdivide_to_size(cushion.vertices, cushion.faces, REFINE_MM, return_index=True)
    fine = trimesh.Trimesh(vertices, faces, process=False)
    return fine, read_only(vertex_thickness_mm(fine, corner[cushion.faces].max(axis=1)[source]))


def _why_uncovered(scan: trimesh.Trimesh | trimesh.PointCloud) -> str:
    """The likely reason a rim finds no skin under it, in words."""
    why = _too_sparse(np.asarray(scan.vertices)) if isinstance(scan, trimesh.PointCloud) else ""
    return why or "is the cushion in this scan's frame, in mm?"


def _too_sparse(cloud: np.ndarray) -> str:
    """Why a point cloud of (N, 3) mm points is too sparse to press a cushion on, in words; "" if not."""
    apart = spacing(cKDTree(cloud))
    if apart <= CLOUD_RADIUS_MM:
        return ""
    return (f"the point cloud's points lie {apart:.1f} mm apart, too sparse to find the skin under the rim "
            f"(it needs points within {CLOUD_RADIUS_MM:g} mm of it): export a denser cloud, or a mesh")


def require_dense(scan: Scan) -> None:
    """InputError for a point cloud too sparse to press a cushion on (`_too_sparse`): asked once the
    template is placed (a sparse cloud that is no face is refused as that), before the gates."""
    why = scan.is_point_cloud and _too_sparse(scan.vertices)
    if why:
        raise InputError(f"{scan.source}: {why}" if scan.source else why)


def spacing(tree: cKDTree, sample: int = 2000) -> float:
    """Median distance (mm) from a scan point to its nearest neighbour (a deterministic sample)."""
    points = tree.data[:: max(1, len(tree.data) // sample)]
    return float(np.median(tree.query(points, k=2)[0][:, 1]))


def _height_over(points: np.ndarray, mesh: trimesh.Trimesh, axes: np.ndarray, reach: float, out: float | None = None,
                 voters: np.ndarray | None = None):
    """(height (V,) mm each of (V, 3) points lies above the skin along its unit axis (V, 3), NaN where
    no skin within `reach`; that skin's normal . axis (V,); out). Inside the skin (the first surface up
    its axis faces out, up the axis) the height is minus the depth to it; else it is the height over
    the first surface below. A point in the air under an overhang (the wing of the nose over the
    groove beside it) is over the groove, not inside the wing. Out (1 or -1, along the normals or
    against them) is the side most of these hits face (of the `voters` (V,) bool's rays, where
    given and any hit) unless given (a mesh wound inside out reads the same)."""
    up, up_facing = _first_hit(points, mesh, axes, reach)
    down, down_facing = _first_hit(points, mesh, -axes, reach)
    if out is None:
        hit = np.isfinite(up), np.isfinite(down)
        if voters is not None and ((hit[0] | hit[1]) & voters).any():
            hit = hit[0] & voters, hit[1] & voters
        facing = np.concatenate([up_facing[hit[0]], -down_facing[hit[1]]])
        out = 1.0 if not len(facing) or np.median(facing) >= 0 else -1.0
    inside = np.isfinite(up) & (out * up_facing > 0)
    return np.where(inside, -up, down), np.where(inside, up_facing, -down_facing), out


def _first_hit(points: np.ndarray, mesh: trimesh.Trimesh, directions: np.ndarray, reach: float):
    """(distance (V,) mm to the first surface along each unit direction (V, 3), NaN where none
    within `reach`; that surface's normal . direction (V,))."""
    first = mesh.ray.intersects_first(points, directions)
    ray = np.flatnonzero(first >= 0)
    tri = first[ray]
    normals = mesh.face_normals[tri]
    _, valid, along = trimesh.intersections.planes_lines(mesh.vertices[mesh.faces[tri, 0]], normals, points[ray], directions[ray],
                                                         return_distance=True)
    ray, along, normals = ray[valid], np.abs(along), normals[valid]
    distance, facing = np.full(len(points), np.nan), np.zeros(len(points))
    distance[ray[along <= reach]] = along[along <= reach]
    facing[ray] = np.einsum("ij,ij->i", normals, directions[ray])
    return distance, facing


def skin_under(points: np.ndarray, mesh: trimesh.Trimesh, axes: np.ndarray, reach: float = REACH_MM) -> np.ndarray:
    """(K,) clearance (mm) of (K, 3) points over the skin under a flange resting there: the median of
    the first hits of rays down the unit axes ((3,), or (K, 3) one per point) from the point and
    PROBE_RAYS points PROBE_MM around it (not one stray triangle at a scan's torn edge, nor one
    noisy sample); NaN where the centre ray misses."""
    axes = np.broadcast_to(axes, points.shape)
    side, other = across(axes)
    turn = np.linspace(0.0, 2 * np.pi, PROBE_RAYS, endpoint=False)[:, None, None]
    ring = PROBE_MM * (np.cos(turn) * side + np.sin(turn) * other)
    probes = points[None] + np.vstack([np.zeros((1,) + points.shape), ring])
    heights = _height_over(probes.reshape(-1, 3), mesh, np.tile(axes, (len(probes), 1)), reach)[0].reshape(len(probes), -1)
    clearance = np.full(len(points), np.nan)
    hit = np.isfinite(heights[0])
    clearance[hit] = np.nanmedian(heights[:, hit], axis=0)
    return clearance


def _skin_below(points: np.ndarray, scan: trimesh.Trimesh | trimesh.PointCloud, axis: np.ndarray):
    """(clearance (K,) mm, skin points (K, 3)) below each point along -axis. A mesh: `skin_under`.
    A point cloud: a plane fitted to the top layer of scan points within CLOUD_RADIUS_MM of the ray,
    its height there kept within theirs (points nearly in a row, at the cloud's edge, tilt the
    plane at random: one such rim point read 390 mm under the skin)."""
    if isinstance(scan, trimesh.Trimesh):
        clearance = skin_under(points, scan, axis)
        return clearance, points - clearance[:, None] * axis
    across = np.linalg.svd(np.eye(3) - np.outer(axis, axis))[0][:, :2]  # two directions across the axis
    cloud = np.asarray(scan.vertices)
    flat, height = cloud @ across, cloud @ axis
    clearance = np.full(len(points), np.nan)
    for i, idx in enumerate(cKDTree(flat).query_ball_point(points @ across, CLOUD_RADIUS_MM)):
        idx = np.asarray(idx, dtype=int)
        idx = idx[height[idx] < points[i] @ axis + REACH_MM]
        if len(idx) >= 3:
            idx = idx[height[idx] > height[idx].max() - CLOUD_LAYER_MM]  # the skin, not what lies behind it
        if len(idx) >= 3:
            design = np.column_stack([np.ones(len(idx)), flat[idx] - points[i] @ across])
            level = np.linalg.lstsq(design, height[idx], rcond=None)[0][0]
            clearance[i] = points[i] @ axis - np.clip(level, height[idx].min(), height[idx].max())  # no wild extrapolation
    return clearance, points - clearance[:, None] * axis


def _skin_planes(skin: np.ndarray, scan: trimesh.Trimesh | trimesh.PointCloud) -> tuple[np.ndarray, np.ndarray]:
    """The scan's plane over NORMAL_MM around each of (K, 3) skin points (NaN rows allowed): (K, 3)
    unit normals, of either sign (NaN where none), and (K, 3) the mean of the scan's points there
    (the point itself where there are none). On a mesh, its vertex normals there that face as the
    nearest vertex's does, summed (not the underside of a wing of the nose beside the groove under
    it), or with no vertex there (a coarse mesh) the nearest triangle's; of a point cloud, the
    least-spread direction of its points there (none with fewer than NORMAL_POINTS). mm."""
    normals, centres = np.full(skin.shape, np.nan), skin.copy()
    found = np.flatnonzero(np.isfinite(skin).all(axis=1))
    points, tree = np.asarray(scan.vertices), scan.kdtree
    nearest = tree.query(skin[found])[1]
    balls = tree.query_ball_point(skin[found], NORMAL_MM)
    count = np.fromiter(map(len, balls), dtype=int, count=len(found))
    ball, row = np.fromiter(chain.from_iterable(balls), dtype=int, count=count.sum()), np.repeat(np.arange(len(found)), count)
    some = count > 0
    centres[found[some]] = _row_sums(points[ball], row, len(found))[some] / count[some, None]
    if isinstance(scan, trimesh.Trimesh):
        own = scan.vertex_normals[nearest]
        around = scan.vertex_normals[ball]
        facing = np.einsum("ij,ij->i", around, own[row]) > 0
        normal = own + _row_sums(around * facing[:, None], row, len(found))
        for i in np.flatnonzero(~some):
            tri = _closest_points(skin[found[i] : found[i] + 1], scan)[1][0]
            normal[i] = scan.face_normals[tri] if tri >= 0 else 0.0
    else:
        normal = np.zeros((len(found), 3))
        for i in np.flatnonzero(count >= NORMAL_POINTS):
            near = points[balls[i]]
            normal[i] = np.linalg.svd(near - near.mean(axis=0), full_matrices=False)[2][-1]
    length = np.linalg.norm(normal, axis=1)
    ok = length > 0  # not a degenerate patch whose normals cancel
    normals[found[ok]] = normal[ok] / length[ok, None]
    return normals, centres


def _row_sums(values: np.ndarray, row: np.ndarray, rows: int) -> np.ndarray:
    """(rows, 3): the sum of the (N, 3) `values` of each row index (N,)."""
    return np.stack([np.bincount(row, weights=values[:, c], minlength=rows) for c in range(3)], axis=1)


def _nearest_skin(points: np.ndarray, clearance: np.ndarray, cos: np.ndarray, scan: trimesh.Trimesh | trimesh.PointCloud,
                  axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(clearance (K,) mm, |cos| (K,)) of (K, 3) rim points, those the axis reads inside the skin
    measured to the nearest skin, where that skin faces the axis at least COS_MIN and lies no more
    than STRAY_MM under the plane of the scan around it (else a flap of a torn edge curled under
    the skin; skin standing over that plane is skin bending away round it, or a triangle spanning
    a crease whose vertices lie below it), over the |cos| of the
    scan's NORMAL_MM normal there, which is how fast the reading changes as the mask moves along
    the axis:
    - under the plane of that skin: inside, by its distance to it (a point cloud's: its depth under
      the plane of its points there);
    - over that plane and, on a mesh, outside the triangle nearest it by the scan's own winding (the
      side most of the skin under the rim faces, `_out_sign`): in the air by its height over the
      plane. The axis went through a sheet whose far side the scan lacks (the wing of the nose seen
      from in front, over the groove beside it);
    - over that plane but behind its nearest triangle, which faces the mask (beside the edge of
      skin the camera saw, in the crease under the wing of the nose): inside, by its distance to it,
      not by the height of the wing over it along the axis. A point past the middle of a sheet
      whose far side is in the scan (its nearest triangle facing away from the mask) stays inside,
      as does any such point over a point cloud (no winding to tell);
    elsewhere, and for points the axis reads in the air, the reading along the axis (`clearance`,
    `cos` (K,); NaN clearances stay)."""
    inside = np.flatnonzero(clearance < 0)
    if not len(inside):
        return clearance, cos
    nearest, tri = _closest_points(points[inside], scan)
    normal, centre = _skin_planes(nearest, scan)
    normal *= np.where(normal @ axis < 0, -1.0, 1.0)[:, None]  # out of the face, towards the mask
    offset = points[inside] - (centre if isinstance(scan, trimesh.PointCloud) else nearest)
    across = np.einsum("ij,ij->i", offset, normal)
    depth = -across if isinstance(scan, trimesh.PointCloud) else np.linalg.norm(offset, axis=1)
    facing = normal @ axis
    trusted = (facing >= COS_MIN) & (np.einsum("ij,ij->i", nearest - centre, normal) >= -STRAY_MM)
    deep, air = trusted & (across < 0), trusted & (across > 0)
    if air.any():  # the scan's winding is read only where a point may be in the air
        out = _out_normals(tri, scan, _out_sign(points, clearance, scan, axis))
        outside = np.einsum("ij,ij->i", offset, out) > 0
        deep |= air & ~outside & (out @ axis > 0)
        air &= outside
    clearance, cos = clearance.copy(), cos.copy()
    clearance[inside[deep]] = -depth[deep] / facing[deep]
    clearance[inside[air]] = across[air] / facing[air]
    cos[inside[deep | air]] = facing[deep | air]
    return clearance, cos


def _out_sign(points: np.ndarray, clearance: np.ndarray, scan: trimesh.Trimesh | trimesh.PointCloud, axis: np.ndarray) -> float:
    """+1 where a mesh's triangles face out of the skin, -1 where it is wound inside out: the side
    the triangles under most of the (K, 3) rim points (along the axis, by their (K,) `clearance`
    mm) face. +1 for a point cloud."""
    hit = np.isfinite(clearance)
    if isinstance(scan, trimesh.PointCloud) or not hit.any():
        return 1.0
    tri = _closest_points(points[hit] - clearance[hit, None] * axis, scan)[1]
    facing = scan.face_normals[tri[tri >= 0]] @ axis
    return 1.0 if not len(facing) or np.median(facing) >= 0 else -1.0


def _out_normals(tri: np.ndarray, scan: trimesh.Trimesh | trimesh.PointCloud, out: float) -> np.ndarray:
    """(K, 3) the unit normals of the triangles `tri` (K,), turned out of the skin by the scan's
    winding `out` (`_out_sign`); zero on a point cloud and where there is no triangle (-1)."""
    if isinstance(scan, trimesh.PointCloud):
        return np.zeros((len(tri), 3))
    return out * scan.face_normals[np.maximum(tri, 0)] * (tri >= 0)[:, None]


def _closest_points(points: np.ndarray, scan: trimesh.Trimesh | trimesh.PointCloud) -> tuple[np.ndarray, np.ndarray]:
    """((K, 3) mm the scan's point nearest each of (K, 3) points, (K,) its triangle or -1): on a
    mesh, on the triangles around its CANDIDATES nearest vertices (a vertex in no triangle: itself);
    of a point cloud, its nearest point."""
    vertices = np.asarray(scan.vertices)
    near = scan.kdtree.query(points, k=min(CANDIDATES, len(vertices)))[1].reshape(len(points), -1)
    out, tri = vertices[near[:, 0]], np.full(len(points), -1)
    if isinstance(scan, trimesh.PointCloud):
        return out, tri
    around = np.asarray(scan.vertex_faces)[near].reshape(len(points), -1)
    row, column = np.nonzero(around >= 0)
    on = trimesh.triangles.closest_point(vertices[np.asarray(scan.faces)[around[row, column]]], points[row])
    order = np.lexsort((np.linalg.norm(on - points[row], axis=1), row))
    first = order[np.unique(row[order], return_index=True)[1]]
    out[row[first]], tri[row[first]] = on[first], around[row[first], column[first]]
    return out, tri


def seal_lengths(rim: np.ndarray) -> np.ndarray:
    """(K,) mm of seal each point of a closed (K, 3) rim, one point a sector, stands for: half the
    distance to each neighbour along the rim smoothed over LENGTH_SECTORS (Gaussian). Where a
    flange meets skin sloping across it, its inner and outer edges press nearly as deep and the
    sectors' rim points jump between them; the seal, and the flange's contact with the skin,
    does not grow longer for that."""
    loop = gaussian_filter1d(rim, LENGTH_SECTORS, axis=0, mode="wrap")
    step = np.linalg.norm(np.roll(loop, -1, axis=0) - loop, axis=1)
    return 0.5 * (step + np.roll(step, 1))


def _area(uv: np.ndarray) -> float:
    """Area (mm^2) of the closed polygon (K, 2) (shoelace)."""
    u, v = uv[:, 0], uv[:, 1]
    return float(0.5 * abs(u @ np.roll(v, -1) - v @ np.roll(u, -1)))
