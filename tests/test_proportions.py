"""The registered face's proportions: a known stretch of the template, in any pose, is read back."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpapfit.align.nonrigid import Registration
from cpapfit.align.similarity import Similarity
from cpapfit.proportions import MIN_MATCHED, proportions
from cpapfit.template import load_template


def posed(stretch, scale: float, valid=None) -> tuple[Similarity, Registration]:
    """The template stretched by (3,) `stretch` along its axes (about its centroid), then scaled,
    turned and moved: the similarity of that pose and the 'registration' it gives."""
    t = load_template().vertices
    rotation = Rotation.from_euler("xyz", [20, -35, 10], degrees=True).as_matrix()
    similarity = Similarity(scale, rotation, np.array([15.0, -40.0, 600.0]), np.ones(1), 0.0, 0)
    face = (t - t.mean(axis=0)) * stretch + t.mean(axis=0)
    valid = np.ones(len(t), dtype=bool) if valid is None else valid
    return similarity, Registration(similarity.apply(face), np.zeros(len(t)), valid)


def test_a_stretch_of_the_template_is_read_back_in_any_pose():
    similarity, registration = posed(np.array([1.1, 0.9, 1.2]), 0.95)
    shape = proportions(load_template().vertices, similarity, registration)
    assert shape.size == pytest.approx(0.95 * np.sqrt(1.1 * 0.9), rel=1e-9)
    assert shape.depth_ratio == pytest.approx(1.2 / np.sqrt(1.1 * 0.9), rel=1e-9)


def test_the_template_itself_is_one_and_one():
    similarity, registration = posed(np.ones(3), 1.0)
    shape = proportions(load_template().vertices, similarity, registration)
    assert (shape.size, shape.depth_ratio) == pytest.approx((1.0, 1.0), rel=1e-9)


def test_too_little_matched_tells_nothing():
    n = len(load_template().vertices)
    similarity, registration = posed(np.ones(3), 1.0, np.arange(n) < MIN_MATCHED - 1)
    shape = proportions(load_template().vertices, similarity, registration)
    assert np.isnan(shape.size) and np.isnan(shape.depth_ratio)
