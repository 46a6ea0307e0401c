"""The affine start: a known stretch of the template is found again from its surface alone."""

import numpy as np
import pytest

from cpapfit.align.affine import IDENTITY, MIN_LANDMARKS, AffineParams, apply_affine, fit_affine, starts_from
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


def fitted(scan: Scan, params: AffineParams = AffineParams(), starts: tuple = (IDENTITY,)) -> np.ndarray:
    v = TEMPLATE.vertices
    target = make_target(scan, use_grid=False, spacing_mm=1.0)
    return fit_affine(v, vertex_normals(v, TEMPLATE.faces), target, WEIGHTS, GATES, params, starts)


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


def test_the_start_pairing_more_of_the_template_wins():
    """A face 30 mm deeper in the scan than the similarity put it: begun there, the fit pairs
    nothing; begun also at a map 2 mm off the truth (as landmarks would give), that start wins,
    preferred or not, and is refined to within 0.3 mm of the truth."""
    linear, shift = np.diag([1.05, 0.97, 1.0]), np.array([0.0, 0.0, 30.0])
    scan = stretched_scan(linear, shift)
    truth = TEMPLATE.vertices @ linear.T + shift
    near = np.hstack([linear, (shift + [1.0, -1.0, 1.4])[:, None]])
    for starts in ((IDENTITY, near), (near, IDENTITY)):
        error = np.linalg.norm(apply_affine(fitted(scan, starts=starts), TEMPLATE.vertices) - truth, axis=1)
        assert error.max() <= 0.3


def test_landmarks_give_their_own_map_as_a_second_start():
    """Landmarks exactly on a stretched template give that map (to 1e-9 mm), preferred to the
    identity; one landmark fewer than MIN_LANDMARKS gives the identity alone; a 40 % stretch is clamped."""
    points = TEMPLATE.vertices[::200][:MIN_LANDMARKS]
    linear, shift = np.array([[1.08, 0.03, 0.0], [0.0, 0.94, 0.02], [0.01, 0.0, 1.03]]), np.array([2.0, -3.0, 1.0])
    first, second = starts_from(points, points @ linear.T + shift, 0.2)
    assert np.abs(first - np.hstack([linear, shift[:, None]])).max() <= 1e-9
    assert np.array_equal(second, IDENTITY)
    assert len(starts_from(points[:-1], points[:-1] @ linear.T + shift, 0.2)) == 1
    clamped, _ = starts_from(points, points @ np.diag([1.4, 1.0, 1.0]).T, 0.2)
    assert np.linalg.svd(clamped[:, :3], compute_uv=False).max() == pytest.approx(1.2, abs=1e-9)
