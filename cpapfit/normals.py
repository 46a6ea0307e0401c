"""Normals of a triangle mesh as trimesh gives them, without a trimesh mesh's cache.

A `trimesh.Trimesh` keeps what its normals were made from (its triangles, their cross products and
angles: ~120 bytes a triangle) for as long as the mesh lives; a mesh made to be ray-cast or pressed
onto needs only the normals.
"""

import numpy as np
import trimesh


def mesh_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((M, 3) unit face normals, zero where a triangle is degenerate; (N, 3) unit vertex normals,
    each its triangles' weighted by their angle there, zero at a vertex in none) of an (N, 3),
    (M, 3) mesh, as trimesh's `Trimesh.face_normals` and `Trimesh.vertex_normals`."""
    corners = vertices[faces]
    unit, valid = trimesh.triangles.normals(corners)
    face = np.zeros((len(faces), 3))
    face[valid] = unit
    return face, trimesh.geometry.weighted_vertex_normals(len(vertices), faces, face, trimesh.triangles.angles(corners))


def lean_mesh(vertices: np.ndarray, faces: np.ndarray) -> trimesh.Trimesh:
    """A `trimesh.Trimesh` of (N, 3), (M, 3) arrays with its face and vertex normals set (`mesh_normals`)."""
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    mesh.face_normals, mesh.vertex_normals = mesh_normals(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    return mesh
