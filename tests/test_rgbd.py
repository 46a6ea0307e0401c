"""Depth-image geometry: back-projection inverts projection; no triangles across depth jumps."""

import numpy as np

from cpapfit.rgbd import backproject, color_to_depth, grid_triangles, project
from cpapfit.scan import Intrinsics

K = Intrinsics(64, 48, 600.0, 620.0, 31.5, 23.0)  # a 64x48 crop of a typical depth camera


def test_backproject_inverts_project():
    depth = np.random.default_rng(0).uniform(300, 700, (48, 64))
    pts = backproject(depth, K).reshape(-1, 3)
    uv = project(pts, K)
    u, v = np.meshgrid(np.arange(64), np.arange(48))
    np.testing.assert_allclose(uv, np.stack([u.ravel(), v.ravel()], 1), atol=1e-9)


def test_step_in_depth_is_not_triangulated_but_slopes_are():
    depth = np.full((48, 64), 500.0)
    depth[:, 32:] = 600.0  # a 100 mm jump between columns 31 and 32
    depth += np.arange(48)[:, None] * 2.0  # a 2 mm/pixel slope (steep, ~60 deg) stays connected
    valid = np.ones_like(depth, dtype=bool)
    valid[10, 10] = False
    pixel_vertex, faces = grid_triangles(depth, valid, K)
    cols = np.argwhere(valid)[:, 1]
    spans_jump = (cols[faces] < 32).any(axis=1) & (cols[faces] >= 32).any(axis=1)
    assert not spans_jump.any()
    assert len(faces) == 2 * 47 * 62 - 6  # two per 2x2 block but those across the jump, minus 6 at the hole
    pts = backproject(depth, K)[valid]
    normals = np.cross(pts[faces[:, 1]] - pts[faces[:, 0]], pts[faces[:, 2]] - pts[faces[:, 0]])
    assert (np.einsum("ij,ij->i", normals, pts[faces[:, 0]]) < 0).all()  # facing the camera


def test_a_small_jump_behind_an_edge_is_not_bridged_but_a_75_degree_slope_is_kept():
    """At 450 mm one pixel is 0.75 mm across: a 7 mm step (the wing of a nostril in front of the
    cheek) is an edge, not skin, while a surface at 75 degrees to the rays (2.8 mm deeper per pixel)
    is skin."""
    step = np.full((48, 64), 450.0)
    step[:, 32:] = 457.0
    valid = np.ones_like(step, dtype=bool)
    cols = np.argwhere(valid)[:, 1]
    faces = grid_triangles(step, valid, K)[1]
    assert not ((cols[faces] < 32).any(axis=1) & (cols[faces] >= 32).any(axis=1)).any()
    footprint = 450.0 / K.fx  # mm per pixel at 450 mm
    slope = 450.0 + np.arange(64)[None, :] * footprint * np.tan(np.radians(75.0)) + np.zeros((48, 1))
    assert len(grid_triangles(slope, valid, K)[1]) == 2 * 47 * 63


def test_grid_boundary_equals_the_edge_definition():
    from cpapfit.rims import boundary_vertices
    from cpapfit.scan import Scan

    rng = np.random.default_rng(1)
    depth = 500.0 + rng.normal(0, 0.2, (48, 64))
    depth[20:30, 5:15] += 80.0  # a step: a rim inside the image
    valid = rng.uniform(size=depth.shape) > 0.05  # scattered holes
    pixel_vertex, faces = grid_triangles(depth, valid, K)
    pts = backproject(depth, K)[valid]
    scan = Scan(vertices=pts, faces=faces, normals=np.zeros_like(pts), depth=depth, valid=valid, pixel_vertex=pixel_vertex, intrinsics=K)
    used = np.bincount(faces.ravel(), minlength=len(pts)) > 0
    assert np.array_equal(scan.rims[used], boundary_vertices(pts, faces)[used])
    assert scan.rims[~used].all()  # a pixel with no triangle is no place to match


def test_a_capture_scan_carries_its_pixels_and_camera():
    """A Scan with a depth image and without its valid mask, its pixels' vertices or its camera, or
    with them of another size or naming vertices it does not have, is no capture: ValueError."""
    from dataclasses import replace

    import pytest

    from cpapfit.scan import Scan

    depth = np.full((48, 64), 500.0)
    valid = np.ones(depth.shape, dtype=bool)
    valid[10:20, 10:20] = False
    depth[~valid] = np.nan
    pixel_vertex, faces = grid_triangles(depth, valid, K)
    pts = backproject(depth, K)[valid]
    scan = Scan(vertices=pts, faces=faces, normals=np.zeros_like(pts), depth=depth, valid=valid, pixel_vertex=pixel_vertex, intrinsics=K)
    assert scan.is_capture
    other = Intrinsics(32, 24, K.fx, K.fy, K.cx, K.cy)
    named_twice, at_a_hole = pixel_vertex.copy(), pixel_vertex.copy()
    named_twice[0, 0] = named_twice[0, 1]
    at_a_hole[15, 15] = 0
    for broken in ({"intrinsics": None}, {"valid": None}, {"pixel_vertex": None}, {"intrinsics": other}, {"valid": valid[:, :32]},
                   {"pixel_vertex": named_twice}, {"pixel_vertex": at_a_hole}, {"pixel_vertex": pixel_vertex.astype(float)},
                   {"valid": valid.astype(float)}, {"depth": depth.ravel()}):
        with pytest.raises(ValueError, match="capture Scan"):
            replace(scan, **broken)


def test_colour_is_registered_to_depth_through_the_extrinsics():
    """A wall 500 mm away seen by a depth camera and a colour camera 25 mm to its right (half the
    depth camera's resolution), whose image codes each pixel's column and row: every depth pixel
    gets the colour pixel its point projects to (nearest); out of the colour view, or without
    depth, black."""
    intr, color_intr = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5), Intrinsics(32, 24, 30.0, 30.0, 15.5, 11.5)
    depth = np.full((48, 64), 500.0)
    depth[:, 5] = np.nan
    v, u = np.indices((24, 32))
    image = np.stack([u, v, np.full_like(u, 200)], axis=-1).astype(np.uint8)
    to_color = np.eye(4)
    to_color[0, 3] = -25.0  # the colour camera sits at x = +25 mm
    registered = color_to_depth(depth, intr, image, color_intr, to_color)
    points = backproject(depth, intr) - [25.0, 0.0, 0.0]
    expected_u = np.round(30.0 * points[..., 0] / 500.0 + 15.5)
    expected_v = np.round(30.0 * points[..., 1] / 500.0 + 11.5)
    seen = np.isfinite(depth) & (expected_u >= 0) & (expected_u < 32)
    assert seen.sum() > 0.7 * depth.size and (~seen & np.isfinite(depth)).any()
    assert np.array_equal(registered[seen][:, 0], expected_u[seen]) and np.array_equal(registered[seen][:, 1], expected_v[seen])
    assert (registered[seen][:, 2] == 200).all() and (registered[~seen] == 0).all()
