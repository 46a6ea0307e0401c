"""The affine start: a known stretch of the template is found again from its surface alone."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import Delaunay

from cpapfit.align.affine import AffineParams, apply_affine, fit_affine
from cpapfit.align.correspondences import make_target
from cpapfit.align.nonrigid import vertex_normals
from cpapfit.scan import Scan
from cpapfit.template import load_template

TEMPLATE = load_template()
GATES = (5.0, 25.0)  # the non-rigid stage's pair rejection: mm, degrees
WEIGHTS = (0.1, 1.0)  # point-to-point, point-to-plane


def stretched_scan(linear: np.ndarray, shift: np.ndarray) -> Scan:
    """The template's surface moved by the affine map (linear, shift), as a mesh scan (mm)."""
    vertices = TEMPLATE.vertices @ linear.T + shift
    return Scan(vertices, TEMPLATE.faces, vertex_normals(vertices, TEMPLATE.faces))


def fitted(scan: Scan, params: AffineParams = AffineParams()) -> np.ndarray:
    v = TEMPLATE.vertices
    target = make_target(scan, use_grid=False, spacing_mm=1.0)
    return fit_affine(v, vertex_normals(v, TEMPLATE.faces), target, WEIGHTS, GATES, params)


def test_a_known_stretch_is_recovered():
    """A face 7 % wider, 5 % shorter, 3 % shallower, slightly sheared and shifted 1.5 mm: every
    vertex lands within 0.3 mm of where the true map puts it (the start was up to ~5 mm off)."""
    linear = np.array([[1.07, 0.02, 0.0], [0.0, 0.95, 0.01], [0.0, 0.0, 0.97]])
    shift = np.array([1.0, -1.0, 0.5])
    affine = fitted(stretched_scan(linear, shift))
    truth = TEMPLATE.vertices @ linear.T + shift
    assert np.abs(TEMPLATE.vertices - truth).max() > 4.0
    assert np.linalg.norm(apply_affine(affine, TEMPLATE.vertices) - truth, axis=1).max() <= 0.3


def test_stretch_is_bounded():
    """A 35 % stretch is beyond adult variation: the map stops at the bound (1 + max_stretch)."""
    affine = fitted(stretched_scan(np.diag([1.35, 1.0, 1.0]), np.zeros(3)), AffineParams(max_stretch=0.2))
    assert np.linalg.svd(affine[:, :3], compute_uv=False).max() == pytest.approx(1.2, abs=1e-9)


def test_no_pairs_gives_the_identity():
    """A scan far from the template (beyond the 5 mm gate) leaves the template where it is."""
    affine = fitted(stretched_scan(np.eye(3), np.array([0.0, 0.0, 50.0])))
    assert np.array_equal(affine, np.hstack([np.eye(3), np.zeros((3, 1))]))


def test_landmarks_pin_the_map_where_the_surface_cannot():
    """On a trough (z = y^2 / 50 mm) a slide along it fits the surface equally well: without
    landmarks the map stays where it starts; 40 landmarks 3 mm along the trough (weight 5 each,
    against 3 721 pairs at 0.1) bring it there (within 0.1 mm)."""
    def trough_of(half_length: float, step: float) -> tuple[np.ndarray, np.ndarray]:
        xy = np.stack(np.meshgrid(np.arange(-half_length, half_length + step / 2, step), np.arange(-30.0, 30.0 + step / 2, step)), -1)
        xy = xy.reshape(-1, 2)
        return np.column_stack([xy, xy[:, 1] ** 2 / 50.0]), Delaunay(xy).simplices

    scan = Scan(*trough_of(45.0, 0.5), None)
    target = make_target(replace(scan, normals=vertex_normals(scan.vertices, scan.faces)), use_grid=False, spacing_mm=0.5)
    trough, faces = trough_of(30.0, 1.0)  # the template: a shorter, coarser stretch of the same trough
    normals = vertex_normals(trough, faces)
    pinned = np.arange(0, len(trough), 93)[:40]
    slid = (pinned, trough[pinned] + [3.0, 0.0, 0.0])
    for landmarks, shift in ((slid, [3.0, 0.0, 0.0]), ((pinned[:0], trough[:0]), [0.0, 0.0, 0.0])):
        moved = apply_affine(fit_affine(trough, normals, target, WEIGHTS, GATES, AffineParams(landmark=5.0), landmarks), trough)
        assert np.abs(moved - trough - shift).max() <= 0.1
