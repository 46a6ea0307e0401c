"""Mesh normals without trimesh's cache: the same numbers as trimesh's, to the bit."""

import numpy as np
import trimesh

from cpapfit.normals import lean_mesh, mesh_normals


def test_mesh_normals_are_trimeshs_to_the_bit_and_leave_no_cache_behind():
    sphere = trimesh.creation.icosphere(4, radius=80.0)
    rng = np.random.default_rng(0)
    bumpy = np.asarray(sphere.vertices) + rng.normal(0.0, 0.3, sphere.vertices.shape)
    vertices = np.vstack([bumpy, [[500.0, 0.0, 0.0]]])  # and one vertex in no triangle
    faces = np.vstack([sphere.faces, [[0, 0, 1], [5, 6, 5]]])  # two degenerate triangles
    reference = trimesh.Trimesh(vertices, faces, process=False)
    face, vertex = mesh_normals(vertices, faces)
    np.testing.assert_array_equal(face, reference.face_normals)
    np.testing.assert_array_equal(vertex, reference.vertex_normals)
    assert not face[-2:].any() and not vertex[-1].any()
    lean = lean_mesh(vertices, faces)
    np.testing.assert_array_equal(lean.vertex_normals, reference.vertex_normals)
    np.testing.assert_array_equal(lean.face_normals, reference.face_normals)
    assert set(lean._cache.cache) <= {"face_normals", "vertex_normals"}  # no triangles, cross products or angles kept
