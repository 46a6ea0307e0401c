import numpy as np
import pytest
import trimesh

from cpapfit.clustering import clustered, cubes, median_edge, thinned
from cpapfit.scan import SEEN_CUBE_MM, Scan

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


def test_a_mesh_scan_denser_than_the_cube_is_seen_thinned_with_its_colours():
    """A 10 mm sphere of ~0.1 mm edges, coloured by height (12 levels a mm), as a mesh scan: seen
    (`Scan.seen`) with its median edge 0.4-0.8 mm (SEEN_CUBE_MM 0.5), within 0.004 mm inside the
    sphere (0.5^2 / (8 x 10) = 0.003 mm), every vertex in a triangle, its normals unit and outwards,
    each colour within a level of the height's at that vertex (the mean of its cube's), the area
    within 1 %; made once. A coarser mesh, a point cloud and a fused sweep are seen as they are."""
    sphere = trimesh.creation.icosphere(7, radius=10.0)

    def colour(v: np.ndarray) -> np.ndarray:
        return np.round(127.5 + 12.0 * v[:, 2:3] * [1.0, -1.0, 0.5]).astype(np.uint8)

    scan = Scan(np.array(sphere.vertices), np.array(sphere.faces), np.array(sphere.vertex_normals), colors=colour(sphere.vertices))
    seen = scan.seen
    assert seen is scan.seen and median_edge(scan.vertices, scan.faces) < 0.15
    assert 0.4 <= median_edge(seen.vertices, seen.faces) <= 0.8 and len(seen.vertices) < len(scan.vertices) / 4
    radius = np.linalg.norm(seen.vertices, axis=1)
    assert (radius <= 10.0 + 1e-9).all() and radius.min() >= 9.996
    assert np.array_equal(np.unique(seen.faces), np.arange(len(seen.vertices)))
    assert np.allclose(np.linalg.norm(seen.normals, axis=1), 1.0) and (np.einsum("ij,ij->i", seen.normals, seen.vertices) > 0).all()
    assert np.abs(seen.colors.astype(int) - colour(seen.vertices)).max() <= 1
    assert trimesh.Trimesh(seen.vertices, seen.faces).area == pytest.approx(sphere.area, rel=0.01)
    coarse = Scan(np.array(SPHERE.vertices) * 2.0, np.array(SPHERE.faces), np.array(SPHERE.vertex_normals))
    cloud = Scan(scan.vertices, np.zeros((0, 3), dtype=np.int64), scan.normals)
    fused = Scan(scan.vertices, scan.faces, scan.normals, fused_frames=2)
    assert median_edge(coarse.vertices, coarse.faces) > SEEN_CUBE_MM
    assert all(other.seen is other for other in (coarse, cloud, fused))


def test_a_dense_textured_mesh_is_seen_with_its_texture_as_colours():
    """The same sphere textured by height (a 256-texel ramp, ~12.8 levels a mm): seen with no
    texture map, each vertex's colour within two levels of the ramp's at its height."""
    sphere = trimesh.creation.icosphere(7, radius=10.0)
    ramp = np.repeat(np.arange(256, dtype=np.uint8)[None, :, None], 3, axis=2)  # (1, 256, 3): red = green = blue = column

    def u(v: np.ndarray) -> np.ndarray:
        return (v[:, 2] + 10.0) / 20.0

    uv = np.column_stack([u(sphere.vertices), np.full(len(sphere.vertices), 0.5)])
    seen = Scan(np.array(sphere.vertices), np.array(sphere.faces), np.array(sphere.vertex_normals), texture=ramp, uv=uv).seen
    assert seen.texture is None and seen.uv is None and len(seen.vertices) < len(sphere.vertices) / 4
    assert np.abs(seen.colors[:, 0].astype(float) - 255.0 * u(seen.vertices)).max() <= 2.0


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


@pytest.mark.parametrize("far_mm", [0.0, 1e15])
def test_points_are_numbered_by_cube_in_row_order_with_a_stray_point_far_off(far_mm):
    """`cubes` at 1 mm: 2000 points within 10 mm numbered by cube in the lexicographic order of the
    cubes' grid rows (as np.unique over the rows), each cube's count right, with and without a
    stray point 1e15 mm off (too far for one int64 key a cube)."""
    rng = np.random.default_rng(3)
    points = np.vstack([rng.uniform(-10.0, 10.0, (2000, 3)), [[far_mm, -far_mm, far_mm]]])
    rows, inverse, count = np.unique(np.floor(points).astype(np.int64), axis=0, return_inverse=True, return_counts=True)
    got, got_count = cubes(points, 1.0)
    assert np.array_equal(got, inverse.reshape(-1)) and np.array_equal(got_count, count)
