"""Solids between trimesh and manifold3d, and whether a surface crosses itself: kernels the cushion,
the mould and the frame share."""

import manifold3d
import numpy as np
import trimesh

PRINT_RESOLUTION_MM = 0.05  # finer than a resin printer resolves
EDGE_CLEARANCE_MM = 1e-3  # a segment hitting a triangle nearer its edge than this passes through the edge (rounding), not the triangle


def to_manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
    """A trimesh solid as a manifold3d Manifold (float32 vertices)."""
    return manifold3d.Manifold(manifold3d.Mesh(vert_properties=mesh.vertices.astype(np.float32), tri_verts=mesh.faces.astype(np.uint32)))


def to_trimesh(m: manifold3d.Manifold) -> trimesh.Trimesh:
    """A manifold3d Manifold as a trimesh solid."""
    mesh = m.to_mesh()
    return trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts), process=False)


def self_intersecting_edges(mesh: trimesh.Trimesh, tol_mm: float = PRINT_RESOLUTION_MM) -> int:
    """How many edges pierce the inside of a triangle they are not part of, from one side of its
    plane to the other (0 for a clean surface; contacts along edges, at corners or in a plane do
    not count, nor folds within `tol_mm` (by default finer than a resin printer resolves), nor hits within
    EDGE_CLEARANCE_MM of a triangle's edge, which pass through the edge): each edge is
    cast as a segment against the mesh (Embree)."""
    edges = mesh.edges_unique[mesh.edges_unique_length > tol_mm]
    start, end = mesh.vertices[edges[:, 0]], mesh.vertices[edges[:, 1]]
    direction = (end - start) / np.linalg.norm(end - start, axis=1, keepdims=True)
    loc, ray, tri = mesh.ray.intersects_location(start, direction, multiple_hits=True)
    corners = mesh.faces[tri]
    foreign = ~((corners == edges[ray, :1]) | (corners == edges[ray, 1:])).any(axis=1)
    corner, normal = mesh.vertices[corners[:, 0]], mesh.face_normals[tri]
    side_start = np.einsum("ij,ij->i", start[ray] - corner, normal)
    side_end = np.einsum("ij,ij->i", end[ray] - corner, normal)
    across = (side_start * side_end < 0) & (np.minimum(np.abs(side_start), np.abs(side_end)) > tol_mm)
    inside = _edge_clearance(mesh.vertices[corners], loc) > EDGE_CLEARANCE_MM
    solid = mesh.area_faces[tri] > tol_mm**2  # slivers from rounding have no side to pierce
    return len(np.unique(ray[foreign & across & inside & solid]))


def _edge_clearance(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(K,) distance (mm) of each point in its (K, 3, 3) triangle's plane from the triangle's
    nearest edge (negative outside): each barycentric coordinate times the height over its edge."""
    bary = trimesh.triangles.points_to_barycentric(triangles, points)
    double_area = np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)
    opposite = np.linalg.norm(np.roll(triangles, -1, axis=1) - np.roll(triangles, 1, axis=1), axis=2)  # edge facing corner i
    return (bary * double_area[:, None] / np.maximum(opposite, 1e-300)).min(axis=1)
