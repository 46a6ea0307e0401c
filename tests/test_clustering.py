import numpy as np
import pytest
import trimesh

from cpapfit.clustering import clustered, thinned

SPHERE = trimesh.creation.icosphere(7, radius=50.0)  # edges ~0.5 mm


def test_vertex_clustering_merges_each_cube_into_the_mean_of_its_vertices():
    """`clustered` at 4 mm on a 50 mm sphere of ~0.5 mm edges: one vertex a cube, the mean of the
    sphere's vertices in it (so within 0.05 mm inside the sphere: 4^2 / (8 x 50) = 0.04 mm); no
    triangle has a repeated corner, repeats another or faces inwards; edges span at most two cubes'
    diagonal; the surface covers the sphere (area within 1 %)."""
    vertices, faces = clustered(np.array(SPHERE.vertices), np.array(SPHERE.faces), 4.0)
    cube = np.floor(vertices / 4.0)
    assert len(faces) < len(SPHERE.faces) / 20
    assert len(np.unique(cube, axis=0)) == len(vertices)
    for k in range(0, len(vertices), 97):
        inside = (np.floor(SPHERE.vertices / 4.0) == cube[k]).all(axis=1)
        assert vertices[k] == pytest.approx(SPHERE.vertices[inside].mean(axis=0), abs=1e-9)
    radius = np.linalg.norm(vertices, axis=1)
    assert (radius <= 50.0 + 1e-9).all() and radius.min() >= 49.95
    assert (faces[:, 0] != faces[:, 1]).all() and (faces[:, 1] != faces[:, 2]).all() and (faces[:, 2] != faces[:, 0]).all()
    assert len(np.unique(np.sort(faces, axis=1), axis=0)) == len(faces)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert (np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center) > 0).all()
    assert mesh.edges_unique_length.max() <= 2 * np.sqrt(3) * 4.0
    assert mesh.area == pytest.approx(SPHERE.area, rel=0.01)


def test_a_mesh_is_thinned_only_where_denser_than_the_cube():
    """The ~0.5 mm sphere thinned at 1 mm: its median edge ~1 mm, within 0.005 mm inside the sphere
    (1 / 400 = 0.0025 mm), no triangle facing inwards, the area within 1 %; at 0.4 mm (coarser
    than that already), a point cloud and a mesh without triangles handed back as they are."""
    thin = thinned(SPHERE, 1.0)
    assert np.median(thin.edges_unique_length) == pytest.approx(1.0, abs=0.25)
    radius = np.linalg.norm(thin.vertices, axis=1)
    assert (radius <= 50.0 + 1e-9).all() and radius.min() >= 49.995
    assert (np.einsum("ij,ij->i", thin.face_normals, thin.triangles_center) > 0).all()
    assert thin.area == pytest.approx(SPHERE.area, rel=0.01)
    assert thinned(SPHERE, 0.4) is SPHERE
    cloud = trimesh.PointCloud(SPHERE.vertices)
    assert thinned(cloud, 1.0) is cloud
    bare = trimesh.Trimesh(SPHERE.vertices, np.zeros((0, 3), dtype=np.int64), process=False)
    assert thinned(bare, 1.0) is bare
