"""The registered face's proportions: a known stretch of the template, in any pose, is read back;
the gates on them; which landmarks are cross-checked against the face's shape alone."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpapfit.align.nonrigid import Registration
from cpapfit.similarity import Similarity
from cpapfit.pipeline import placed_by_shape
from cpapfit.quality.proportions import Proportions, proportions
from cpapfit.thresholds import MIN_MATCHED
from cpapfit.quality.gates import _shape_gates
from cpapfit.thresholds import QualityParams
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


CAPTURE, MESH = SimpleNamespace(is_capture=True), SimpleNamespace(is_capture=False)


@pytest.mark.parametrize("size,ratio,flagged,refused", [
    (1.0, 1.0, set(), set()),
    (0.75, 1.0, {"face_size"}, set()),
    (0.6, 1.0, {"face_size"}, {"face_size"}),
    (1.3, 1.0, {"face_size"}, set()),
    (1.0, 0.8, set(), set()),
    (1.0, 0.7, {"depth_ratio"}, set()),
    (1.0, 1.3, {"depth_ratio"}, set()),
    (1.0, 1.4, {"depth_ratio"}, {"depth_ratio"}),
    (1.0, 0.6, {"depth_ratio"}, {"depth_ratio"}),
])
def test_the_shape_gates_judge_each_side(size, ratio, flagged, refused):
    gates = _shape_gates(CAPTURE, Proportions(size, ratio), QualityParams())
    assert [g.code for g in gates] == ["depth_ratio", "face_size"]
    assert {g.code for g in gates if g.flag} == flagged and {g.code for g in gates if g.refuse} == refused


def test_the_shape_gates_say_what_to_check():
    """A capture: which way the focal length is off, and a child's face as the other cause of a small
    one; a mesh: its units, and a stretch (a mesh has no focal length to check)."""
    flat, deep = (_shape_gates(CAPTURE, Proportions(0.7, r), QualityParams())[0].message for r in (0.8, 1.25))
    assert "too short makes the face k times too flat and the mask k times too wide" in flat
    assert "too long makes the face k times too deep and the mask k times too narrow" in deep
    small = _shape_gates(CAPTURE, Proportions(0.75, 1.0), QualityParams())[1].message
    assert "depth scale and intrinsics" in small and "a child's face" in small
    ratio, size = (g.message for g in _shape_gates(MESH, Proportions(1.3, 1.25), QualityParams()))
    assert "stretched or squashed" in ratio and "focal" not in ratio and "--units" in size and "child" not in size


def test_a_size_without_a_depth_ratio_is_still_judged():
    """A map with no breadth (a degenerate registration): size 0, refused; no depth ratio to judge."""
    gates = _shape_gates(CAPTURE, Proportions(0.0, np.nan), QualityParams())
    assert [(g.code, g.refuse) for g in gates] == [("face_size", True)]


@pytest.mark.parametrize("path,spread", [("user", 7.0), ("fallback", np.nan), ("image", 4.9), ("render", 10.5)])
def test_only_doubtful_detected_landmarks_are_cross_checked(path, spread):
    """Not a user's file or the fallback; detected landmarks only past 5 mm of spread, and not past
    10 mm (`registered` has then tried the shape alone already)."""
    alignment = SimpleNamespace(landmarks=SimpleNamespace(path=path))
    assert placed_by_shape(None, alignment, SimpleNamespace(landmark_spread_mm=spread)) is None
