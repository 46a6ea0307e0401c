"""Ray-cast rendering of a mesh through a pinhole camera: exact depth and simple shading.

Used for synthetic subjects (depth and colour images) and for pictures. Camera frame is
OpenCV's (x right, y down, z forward), mm. Embree finds the first triangle hit by each pixel's
ray; the hit point is then recomputed exactly in float64.
"""

from dataclasses import dataclass

import numpy as np
import trimesh
from trimesh.ray.ray_pyembree import RayMeshIntersector

from .frozen import freeze_arrays
from .normals import mesh_normals
from .rgbd import pixel_rays
from .scan import Intrinsics, texels


LIGHT = np.array([-0.3, -0.4, -1.0])  # towards the light, camera frame: above left of the camera
LIGHT.flags.writeable = False
BACKGROUND = np.array([0.55, 0.58, 0.62])
BACKGROUND.flags.writeable = False


@dataclass(frozen=True)
class Hits:
    """Where each pixel's ray meets the mesh.

    triangle: (H, W) int64 index of the triangle hit, -1 where the ray misses.
    bary: (H, W, 3) float64 barycentric coordinates of the hit in that triangle.
    depth: (H, W) float64 z of the hit in mm, NaN where the ray misses.
    cos_incidence: (H, W) float64 |cos| of the angle between the ray and the triangle normal.
    """

    triangle: np.ndarray
    bary: np.ndarray
    depth: np.ndarray
    cos_incidence: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)

    @property
    def hit(self) -> np.ndarray:
        """(H, W) bool: the ray meets the mesh."""
        return self.triangle >= 0


@dataclass(frozen=True)
class Scene:
    """A triangle mesh to be seen from many cameras (mm, its own frame): (N, 3) vertices, (M, 3)
    faces, (N, 3) unit vertex normals and its Embree scene, built once."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    intersector: RayMeshIntersector

    def __post_init__(self):
        freeze_arrays(self)

    def __reduce__(self):
        """Pickled (for a worker process) as its mesh, its Embree scene built again there."""
        return scene_of, (self.vertices, self.faces)


def scene_of(vertices: np.ndarray, faces: np.ndarray) -> Scene:
    """The `Scene` of an (N, 3) mm mesh: its Embree scene and vertex normals (`normals.mesh_normals`)."""
    return Scene(vertices, faces, mesh_normals(vertices, faces)[1], RayMeshIntersector(trimesh.Trimesh(vertices, faces, process=False)))


def look(scene: Scene, view) -> tuple[Hits, np.ndarray, np.ndarray]:
    """A scene seen from a `view` (`landmarks.views.View`: rays cast in the scene's own frame):
    (hits, (N, 3) camera-frame vertices, (N, 3) camera-frame normals)."""
    dirs = unit_rays(view.intrinsics) @ view.rotation
    first = scene.intersector.intersects_first(np.tile(view.to_scan(np.zeros((1, 3))), (len(dirs), 1)), dirs)
    vertices = view.to_camera(scene.vertices)
    return raycast(vertices, scene.faces, view.intrinsics, first), vertices, scene.normals @ view.rotation.T


def unit_rays(intrinsics: Intrinsics) -> np.ndarray:
    """(H * W, 3) unit directions of the pixel centres' rays, camera frame, row by row."""
    rays = pixel_rays(intrinsics).reshape(-1, 3)
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)


def raycast(vertices: np.ndarray, faces: np.ndarray, intrinsics: Intrinsics, first: np.ndarray | None = None) -> Hits:
    """Cast one ray per pixel centre from the camera origin onto an (N, 3) mm camera-frame mesh.
    first: the (H * W,) triangle each ray meets first (-1: none), if already cast (in any frame:
    a mesh's Embree scene is then built once for many views)."""
    rays = pixel_rays(intrinsics).reshape(-1, 3)
    dirs = unit_rays(intrinsics)
    if first is None:
        first = RayMeshIntersector(trimesh.Trimesh(vertices, faces, process=False)).intersects_first(np.zeros_like(dirs), dirs)
    tri = np.asarray(first, dtype=np.int64)
    shape = (intrinsics.height, intrinsics.width)
    bary = np.zeros((len(rays), 3))
    depth = np.full(len(rays), np.nan)
    cos = np.zeros(len(rays))
    hit = tri >= 0
    a, b, c = (vertices[faces[tri[hit], k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    r = rays[hit]
    t = np.einsum("ij,ij->i", normal, a) / np.einsum("ij,ij->i", normal, r)  # ray p = t * r, r_z = 1
    p = r * t[:, None]
    bary[hit] = trimesh.triangles.points_to_barycentric(np.stack([a, b, c], axis=1), p)
    depth[hit] = t
    cos[hit] = np.abs(np.einsum("ij,ij->i", normal, dirs[hit]))
    return Hits(tri.reshape(shape), bary.reshape(*shape, 3), depth.reshape(shape), cos.reshape(shape))


def interpolate(hits: Hits, faces: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(H, W, C) per-vertex (N, C) values interpolated at each hit; zeros where rays miss."""
    out = np.zeros((*hits.triangle.shape, values.shape[1]))
    hit = hits.hit
    corners = values[faces[hits.triangle[hit]]]  # (K, 3, C)
    out[hit] = np.einsum("kj,kjc->kc", hits.bary[hit], corners)
    return out


def sample_texture(hits: Hits, faces: np.ndarray, uv: np.ndarray, texture: np.ndarray) -> np.ndarray:
    """(H, W, 3) albedo in [0, 1] looked up (nearest texel) in an (h, w, 3) uint8 texture at each hit.

    uv: (N, 2) per-vertex texture coordinates, origin at the image's bottom-left (OBJ/glTF as trimesh gives)."""
    return texels(texture, interpolate(hits, faces, uv))


def shade(
    hits: Hits,
    vertices: np.ndarray,
    faces: np.ndarray,
    albedo: np.ndarray,
    light: np.ndarray = LIGHT,
    ambient: float = 0.35,
    background: np.ndarray = BACKGROUND,
    normals: np.ndarray | None = None,
) -> np.ndarray:
    """(H, W, 3) uint8 Lambert-shaded image of a mesh, albedo in [0, 1] per vertex (N, 3) or per pixel (H, W, 3).

    `light` is the direction from the surface towards the light in the camera frame; `normals`:
    the (N, 3) vertex normals in the camera frame, if known (else computed from the mesh).
    """
    if normals is None:
        normals = trimesh.Trimesh(vertices, faces, process=False).vertex_normals
    n = interpolate(hits, faces, np.asarray(normals))
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    to_light = light / np.linalg.norm(light)
    lambert = np.clip(np.abs(n @ to_light), 0.0, 1.0)  # two-sided: winding does not matter
    per_pixel = albedo.shape[:2] == hits.triangle.shape and albedo.ndim == 3
    rgb = (albedo if per_pixel else interpolate(hits, faces, albedo)) * (ambient + (1.0 - ambient) * lambert)[..., None]
    rgb[~hits.hit] = background
    return np.clip(np.round(rgb * 255.0), 0, 255).astype(np.uint8)
