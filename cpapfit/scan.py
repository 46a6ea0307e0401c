"""The `Scan` type every stage reads: a face surface in millimetres, with what the sensor gave."""

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from .clustering import clusters, cube_means, median_edge
from .frozen import freeze_arrays
from .normals import mesh_normals
from .rims import boundary_vertices, cloud_boundary, grid_boundary

SEEN_CUBE_MM = 0.5  # a mesh scan denser than this (median edge) is seen thinned to cubes this size (finer than rims are read)


def texels(texture: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """(..., 3) colour in [0, 1] of an (h, w, 3) uint8 texture at (..., 2) texture coordinates
    (nearest texel; origin at the image's bottom-left)."""
    th, tw = texture.shape[:2]
    col = np.clip(np.round(coords[..., 0] * (tw - 1)), 0, tw - 1).astype(np.int64)
    row = np.clip(np.round((1.0 - coords[..., 1]) * (th - 1)), 0, th - 1).astype(np.int64)
    return texture[row, col, :3] / 255.0


def robust_extent(vertices: np.ndarray) -> float:
    """Largest 1st-to-99th percentile extent along x, y or z of (N, 3) vertices, in their units."""
    lo, hi = np.percentile(vertices, [1.0, 99.0], axis=0)
    return float((hi - lo).max())


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole camera intrinsics (pixels) of a `width` x `height` image, OpenCV convention."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def matrix(self) -> np.ndarray:
        """The 3x3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


def _require_capture_parts(scan: "Scan") -> None:
    """ValueError unless a scan with a depth image (a capture) carries what its stages read with it:
    `valid` and `pixel_vertex` of the depth image's (H, W), `pixel_vertex` naming each vertex once at
    exactly the valid pixels, and `intrinsics` of that size."""
    if scan.depth is None:
        return
    shape = np.shape(scan.depth)
    if scan.valid is None or scan.pixel_vertex is None or scan.intrinsics is None:
        raise ValueError("a capture Scan (with depth) needs valid, pixel_vertex and intrinsics")
    valid, pixel_vertex = np.asarray(scan.valid), np.asarray(scan.pixel_vertex)
    if len(shape) != 2 or valid.dtype != bool or not np.issubdtype(pixel_vertex.dtype, np.integer):
        raise ValueError("a capture Scan's depth is an (H, W) image, its valid mask bool and its pixel_vertex integers")
    if valid.shape != shape or pixel_vertex.shape != shape or (scan.intrinsics.height, scan.intrinsics.width) != shape:
        raise ValueError(f"a capture Scan's valid, pixel_vertex and intrinsics must be of its depth image's size {shape[1]}x{shape[0]}")
    if (pixel_vertex[~valid] != -1).any() or not np.array_equal(np.sort(pixel_vertex[valid]), np.arange(len(scan.vertices))):
        raise ValueError("a capture Scan's pixel_vertex must name each vertex once, at its valid pixels (-1 elsewhere)")


@dataclass(frozen=True)
class Scan:
    """A facial scan in millimetres.

    vertices: (N, 3) float64 mm, in the scan's own frame (camera frame x right, y down,
        z forward for RGB-D captures).
    faces: (M, 3) int64 triangles; (0, 3) for a point cloud.
    normals: (N, 3) float64 unit vertex normals (towards the sensor for RGB-D).
    colors: (N, 3) uint8 per-vertex colour, or None.
    texture, uv: (H, W, 3) uint8 texture image and (N, 2) float64 texture coordinates, or None.
    image: (H, W, 3) uint8 colour image registered to the depth image, or None.
    depth: (H, W) float64 depth in mm, NaN where invalid, or None.
    valid: (H, W) bool mask of valid depth pixels, or None.
    pixel_vertex: (H, W) int64 index of the vertex of each valid pixel, -1 elsewhere, or None.
    intrinsics: camera intrinsics of image and depth, or None.
    source: the path the scan was read from.
    units: the unit the input was in (a key of `io.units.MM_PER_UNIT`: "mm", "cm", "m", "um" or "in").
    units_note: how that unit was decided, in words.
    fused_frames: how many depth frames were fused into this mesh (a sweep), 0 for any other scan.
    A capture (depth given) carries valid, pixel_vertex and intrinsics of its depth image's size,
    pixel_vertex naming each vertex once at exactly the valid pixels, -1 elsewhere (ValueError otherwise).
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    source: str = ""
    units: str = "mm"
    units_note: str = ""
    colors: np.ndarray | None = None
    texture: np.ndarray | None = None
    uv: np.ndarray | None = None
    image: np.ndarray | None = None
    depth: np.ndarray | None = None
    valid: np.ndarray | None = None
    pixel_vertex: np.ndarray | None = None
    intrinsics: Intrinsics | None = None
    fused_frames: int = 0

    def __post_init__(self):
        _require_capture_parts(self)
        freeze_arrays(self)

    @property
    def is_point_cloud(self) -> bool:
        """True when the scan has no triangles."""
        return len(self.faces) == 0

    @property
    def is_capture(self) -> bool:
        """True when the scan came from a depth image (grid correspondences possible)."""
        return self.depth is not None

    @property
    def is_mesh(self) -> bool:
        """True for a triangle mesh not from a depth image (seen by rendering it)."""
        return not self.is_capture and not self.is_point_cloud

    @cached_property
    def rims(self) -> np.ndarray:
        """(N,) bool, read-only: the points on the scan's edge and the edges of its holes (rims.py),
        found once per scan (a large cloud's take seconds)."""
        if self.is_capture:
            out = grid_boundary(len(self.vertices), self.faces)
        elif self.is_point_cloud:
            out = cloud_boundary(self.vertices, self.normals)
        else:
            out = boundary_vertices(self.vertices, self.faces)
        out.flags.writeable = False
        return out

    @cached_property
    def seen(self) -> "Scan":
        """The scan as it is looked at: its landmarks found and the alignment checked on it, its
        pictures drawn from it, the surface cushions are pressed on cut from it. A scanner's mesh
        (not a capture or a fused sweep) whose median edge is under SEEN_CUBE_MM, its vertices in
        each cube that size merged (`clustering.clustered`: within microns of its surface), their
        colours (a texture map's at each vertex) averaged, its normals those of the merged mesh; any
        other scan itself. Its registration and the quality gates' own readings of the skin (rim
        gaps, holes, depth) are on the scan itself; a dense mesh's design reads within the figures
        of `bench/RESULTS.md` section 5 of one with its landmarks found on the whole scan."""
        if not self.is_mesh or self.fused_frames or median_edge(self.vertices, self.faces) >= SEEN_CUBE_MM:
            return self
        used, cube, vertices, faces = clusters(self.vertices, self.faces, SEEN_CUBE_MM)
        kept = np.unique(faces)  # the merged vertices some triangle still uses
        rgb = 255.0 * texels(self.texture, self.uv) if self.texture is not None else self.colors
        colors = None if rgb is None else np.round(cube_means(rgb[used], cube, np.bincount(cube))[kept]).astype(np.uint8)
        vertices, faces = vertices[kept], np.searchsorted(kept, faces)
        return replace(self, vertices=vertices, faces=faces, normals=mesh_normals(vertices, faces)[1], colors=colors, texture=None, uv=None)


def scan_surface(scan: Scan, near: np.ndarray | None = None, reach_mm: float = np.inf) -> trimesh.Trimesh | trimesh.PointCloud:
    """The scan as trimesh sees it (its triangles, or its points for a point cloud); given (K, 3) mm
    points `near`, only its part within `reach_mm` of one of them: a cloud's points, a mesh's
    triangles with a point that near (a corner within the reach and the triangle's longest edge)
    and its points that near with no triangle, in their order; the whole scan where nothing is that
    near. A design builds it once and hands it to every stage, so that its k-d tree and Embree scene
    are built once, over no more of the head than it needs."""
    vertices, faces = scan.vertices, scan.faces
    keep, kept = np.ones(len(vertices), dtype=bool), faces
    if near is not None:
        corners = vertices[faces]
        longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1) if len(faces) else np.zeros(0)
        distance = cKDTree(near).query(vertices, distance_upper_bound=reach_mm + longest.max(initial=0.0))[0]
        kept = faces[(distance[faces].min(axis=1) <= reach_mm + longest)]
        keep = distance <= reach_mm
        keep[kept.ravel()] = True
        if not keep.any():
            keep, kept = np.ones(len(vertices), dtype=bool), faces
    if scan.is_point_cloud:
        return trimesh.PointCloud(vertices[keep])
    index = np.cumsum(keep) - 1
    return trimesh.Trimesh(vertices[keep], index[kept], process=False)
