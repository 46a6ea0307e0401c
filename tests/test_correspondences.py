"""The scan as the registration's target: a coarse mesh scan subdivided without cracks, its rims and
normals; its nearest points those a brute-force search finds, in a forked process too; and the
registration on the shared fran scan (3 mm triangles) lying on the scan's real surface."""

import multiprocessing
from pathlib import Path

import numpy as np
import pytest
import trimesh

from cpapfit.align.correspondences import _subdivided_normals, lookup, make_target, subdivided
from cpapfit.nearest import NearestPoints
from cpapfit.rims import boundary_vertices, cloud_boundary, edge_uses
from cpapfit.scan import Scan
from cpapfit.io import load_scan
from cpapfit.pipeline import align, register_template
from cpapfit.template import load_template, mask_region


def holed_sphere():
    """A 40 mm sphere of ~3.5 mm triangles with a cap cut off (one rim)."""
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=40.0)
    mesh = trimesh.Trimesh(sphere.vertices, sphere.faces[sphere.triangles_center[:, 2] < 30.0], process=False)
    mesh.remove_unreferenced_vertices()
    return mesh


def test_subdivision_keeps_the_surface_and_its_only_rim():
    mesh = holed_sphere()
    vertices, faces = subdivided(mesh.vertices, mesh.faces, 1.0)
    edges = np.linalg.norm(vertices[faces[:, 0]] - vertices[faces[:, 1]], axis=1)
    assert np.median(edges) <= 1.0 < 2.0 * np.median(edges)  # as few halvings as it takes
    _, dist, _ = trimesh.proximity.closest_point(mesh, vertices)
    assert dist.max() < 1e-9  # new vertices lie on the original triangles
    rim = boundary_vertices(vertices, faces)
    on_rim_before = boundary_vertices(mesh.vertices, mesh.faces)
    rim_edges = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).outline().entities
    assert rim.sum() == 2 ** 2 * on_rim_before.sum() == 2 ** 2 * sum(len(e.points) - 1 for e in rim_edges)
    assert len(np.unique(vertices, axis=0)) == len(vertices)  # midpoints shared: no cracks


def test_a_coarse_scan_made_a_target_keeps_its_rim_and_faces_out():
    mesh = holed_sphere()
    scan = Scan(np.array(mesh.vertices), np.array(mesh.faces), np.array(mesh.vertex_normals))
    target = make_target(scan, use_grid=False, spacing_mm=1.0)
    vertices, faces = subdivided(scan.vertices, scan.faces, 1.5)
    np.testing.assert_array_equal(target.vertices, vertices)
    np.testing.assert_array_equal(target.boundary, boundary_vertices(vertices, faces))
    np.testing.assert_array_equal(target.normals, _subdivided_normals(scan, vertices, faces))
    outward = np.einsum("ij,ij->i", target.normals, vertices / np.linalg.norm(vertices, axis=1, keepdims=True))
    assert outward.min() > 0.97  # the sphere's own normals, within its 3.5 mm facets' bend
    on_rim = np.abs(vertices[:, 2] - vertices[target.boundary, 2].mean()) < 2.0
    assert not np.any(target.boundary & ~on_rim)  # rims only at the cut


def test_edge_uses_counts_each_edge_once_either_way_round():
    faces = np.array([[0, 1, 2], [2, 1, 3], [1, 0, 4], [0, 1, 5], [3, 6, 2]])
    counted = {}
    for face in faces.tolist():
        for a, b in zip(face, face[1:] + face[:1]):
            counted[min(a, b), max(a, b)] = counted.get((min(a, b), max(a, b)), 0) + 1
    for dtype in (np.int32, np.int64):
        edges, uses = edge_uses(faces.astype(dtype))
        assert [tuple(e) for e in edges.tolist()] == sorted(counted)  # each pair ascending, in ascending order
        assert uses.tolist() == [counted[e] for e in sorted(counted)]  # (0, 1) three times, (1, 2) and (2, 3) twice


def _nearest(points: np.ndarray, queries: np.ndarray) -> np.ndarray:
    return NearestPoints(points).query(queries)[1]


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="finds the OpenMP runtimes in Linux's /proc/self/maps")
def test_a_process_forked_after_queries_finds_the_same_points():
    rng = np.random.default_rng(5)
    points, queries = rng.uniform(-20.0, 20.0, (100_000, 3)), rng.uniform(-25.0, 25.0, (50_000, 3))
    here = _nearest(points, queries)  # OpenMP's threads started in this thread, which then forks
    with multiprocessing.get_context("fork").Pool(1) as pool:
        there = pool.apply_async(_nearest, (points, queries)).get(timeout=30)  # waited for ever without `nearest._one_thread`
    np.testing.assert_array_equal(there, here)


def test_nearest_points_are_those_a_brute_force_search_finds():
    rng = np.random.default_rng(3)
    points = rng.uniform(-20.0, 20.0, (3000, 3))
    queries = rng.uniform(-30.0, 30.0, (2000, 3))
    every = np.linalg.norm(queries[:, None, :] - points[None, :, :], axis=2)
    nearest = every.argmin(axis=1)
    tree = NearestPoints(points)
    dist, index = tree.query(queries)
    np.testing.assert_array_equal(index, nearest)
    np.testing.assert_allclose(dist, every.min(axis=1), rtol=0, atol=1e-12)
    bound = float(np.median(every.min(axis=1)))
    dist, index = tree.query(queries, bound)
    within = every.min(axis=1) < bound
    np.testing.assert_array_equal(index, np.where(within, nearest, len(points)))
    assert np.isinf(dist[~within]).all() and index.dtype == np.int64
    pair = NearestPoints(np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]]))
    assert pair.query(np.array([[2.0, 0.0, 0.0]]), 2.0)[1][0] == 2  # 2 mm off is not nearer than 2 mm
    assert pair.query(np.array([[2.0, 0.0, 0.0]]), 2.001)[1][0] == 0


def test_an_empty_tree_or_bound_finds_nothing_and_a_point_off_the_numbers_is_refused():
    dist, index = NearestPoints(np.zeros((0, 3))).query(np.ones((4, 3)))
    assert np.isinf(dist).all() and (index == 0).all()
    tree = NearestPoints(np.ones((5, 3)))
    dist, index = tree.query(np.zeros((0, 3)))
    assert dist.shape == index.shape == (0,)
    for bound in (0.0, -1.0, np.nan):
        dist, index = tree.query(np.ones((2, 3)), bound)
        assert np.isinf(dist).all() and (index == 5).all()
    with pytest.raises(ValueError, match="not finite"):
        tree.query(np.array([[0.0, np.nan, 0.0]]))
    with pytest.raises(ValueError, match="not \\(K, 3\\)"):
        tree.query(np.ones(3))


def test_lookup_marks_the_unpaired():
    mesh = holed_sphere()
    scan = Scan(np.array(mesh.vertices), np.array(mesh.faces), np.array(mesh.vertex_normals))
    target = make_target(scan, use_grid=False, spacing_mm=10.0)  # not subdivided: the scan itself
    far = np.array([[0.0, 0.0, 100.0], scan.vertices[7] * 1.001])
    np.testing.assert_array_equal(lookup(target, far, 5.0), [-1, 7])


@pytest.mark.shared
def test_fran_registers_onto_its_real_surface(shared_data):
    """fran's 3 mm triangles are subdivided for the k-d tree; the registered mask region must lie on
    the scan's triangles themselves (closest point), not only near the subdivision's vertices."""
    scan = load_scan(shared_data / "fran_cyberware" / "fran.obj")
    reg = register_template(scan, align(scan))
    region = mask_region(load_template())
    _, dist, _ = trimesh.proximity.closest_point(trimesh.Trimesh(scan.vertices, scan.faces, process=False), reg.vertices[region])
    near = dist[dist < 3.0]  # the rest is over holes and beyond the scan's edge
    assert len(near) > 0.95 * len(dist)
    assert np.median(near) <= 0.15 and np.percentile(near, 95) <= 1.5


def test_a_point_clouds_rim_is_found_and_its_inside_is_not():
    """40 000 points scattered at random on a 100 mm square (0.5 mm apart): of those more than 5 mm
    inside, at most 0.5 % are taken for rim (PCL's 90 degrees over 16 neighbours: 26 %); of those
    within a quarter spacing of the edge, at least 95 %. Counted in chunks or at once: the same; and
    a `Scan` of those points finds them once and keeps them read-only."""
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(0.0, 100.0, (40_000, 2)), np.zeros(40_000)])
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    rim = cloud_boundary(points, normals)
    inside = (np.abs(points[:, :2] - 50.0) < 45.0).all(axis=1)
    edge = (points[:, :2].min(axis=1) < 0.125) | (points[:, :2].max(axis=1) > 99.875)
    assert rim[inside].mean() <= 0.005 and rim[edge].mean() >= 0.95
    assert np.array_equal(rim, cloud_boundary(points, normals, chunk=7_000))
    scan = Scan(vertices=points, faces=np.zeros((0, 3), dtype=np.int64), normals=normals)
    assert np.array_equal(scan.rims, rim) and scan.rims is scan.rims and not scan.rims.flags.writeable
