import numpy as np
import pytest
import trimesh

from cpapfit.clustering import clustered, thinned

SPHERE = trimesh.creation.icosphere(7, radius=50.0)  # edges ~0.5 mm


def test_vertex_clustering_merges_each_cube_into_the_mean_of_its_vertices():
    """`clustered` at 4 mm on a 50 mm sphere of ~0.5 mm edges: one vertex a cube, within 0.05 mm of
    the sphere (the mean of a cube's points on it: 4^2 / (8 x 50) = 0.04 mm inside); no triangle
    has a repeated corner, repeats another or faces inwards; edges span at most two cubes'
    diagonal; the surface covers the sphere (area within 1 %)."""
    vertices, faces = clustered(np.array(SPHERE.vertices), np.array(SPHERE.faces), 4.0)
    assert len(faces) < len(SPHERE.faces) / 20
    assert len(np.unique(np.floor(vertices / 4.0), axis=0)) == len(vertices)
    assert np.abs(np.linalg.norm(vertices, axis=1) - 50.0).max() <= 0.05
    assert (faces[:, 0] != faces[:, 1]).all() and (faces[:, 1] != faces[:, 2]).all() and (faces[:, 2] != faces[:, 0]).all()
    assert len(np.unique(np.sort(faces, axis=1), axis=0)) == len(faces)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert (np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center) > 0).all()
    assert mesh.edges_unique_length.max() <= 2 * np.sqrt(3) * 4.0
    assert mesh.area == pytest.approx(SPHERE.area, rel=0.01)


def test_a_mesh_is_thinned_only_where_denser_than_the_cube():
    """The ~0.5 mm sphere thinned at 1 mm: its median edge ~1 mm, within 0.02 mm of the sphere; at
    0.4 mm (coarser than that already), and a point cloud, handed back as they are."""
    thin = thinned(SPHERE, 1.0)
    assert np.median(thin.edges_unique_length) == pytest.approx(1.0, abs=0.25)
    assert np.abs(np.linalg.norm(thin.vertices, axis=1) - 50.0).max() <= 0.02
    assert thinned(SPHERE, 0.4) is SPHERE
    cloud = trimesh.PointCloud(SPHERE.vertices)
    assert thinned(cloud, 1.0) is cloud
