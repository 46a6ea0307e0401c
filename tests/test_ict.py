"""The ICT face model shipped in the package, and the template mapped onto its topology."""

from importlib import resources

import numpy as np
import pytest
import trimesh

from cpapfit.errors import InputError
from cpapfit.ict import EXPRESSIONS, MULTIPIE_TO_FACEMESH, ict_face, jaw_open_weight, load_ict, random_subject, template_truth
from cpapfit.template import load_template

FLOAT16_MM = 0.02  # the largest rounding error of a float16 mode (the model's modes are under 40 mm)


@pytest.mark.shared
def test_the_shipped_model_is_the_shared_one_turned_into_the_template_frame(shared_data):
    full = np.load(shared_data / "ict_face_model" / "ict_face_model.npz")
    shipped = np.load(resources.files("cpapfit.ict").joinpath("data", "ict_face.npz"))
    r, t = shipped["rotation"], shipped["translation_mm"]
    model = load_ict()
    k = len(model.identity)
    np.testing.assert_allclose(model.neutral, full["neutral_mm"] @ r.T + t, atol=1e-4)
    assert np.abs(model.identity - full["identity_mm"][:k] @ r.T).max() < FLOAT16_MM
    names = list(full["expression_names"])
    assert np.abs(model.expressions - full["expression_mm"][[names.index(n) for n in EXPRESSIONS]] @ r.T).max() < FLOAT16_MM
    assert np.array_equal(model.triangles, full["triangles"]) and np.array_equal(model.landmarks, full["landmarks_multipie68"])
    assert np.allclose(r @ r.T, np.eye(3)) and np.isclose(np.linalg.det(r), 1.0)  # rigid: no scale, no mirror


@pytest.mark.shared
def test_the_full_model_is_the_shipped_one_with_all_its_modes(shared_data):
    """load_ict(path): the original file in full, in the shipped model's frame; its subjects lie off
    the span of the shipped 40 modes (5 seeds, face area, least-squares projection on those modes:
    mean 0.58-0.90 mm, max 2.3-3.8 mm)."""
    path = shared_data / "ict_face_model" / "ict_face_model.npz"
    full, shipped = load_ict(path), load_ict()
    assert load_ict(str(path)) is full and load_ict() is shipped  # read once per path
    k, f = len(shipped.identity), shipped.face_vertices
    assert len(full.identity) == 100 and full.identity.dtype == np.float64 and full.identity_share == 1.0
    assert np.abs(full.neutral - shipped.neutral).max() < 0.05  # mm
    assert np.abs(full.identity[:k] - shipped.identity).max() < FLOAT16_MM
    assert full.expression_names == shipped.expression_names and np.abs(full.expressions - shipped.expressions).max() < FLOAT16_MM
    assert np.array_equal(full.triangles, shipped.triangles) and np.array_equal(full.landmarks, shipped.landmarks)
    assert abs(jaw_open_weight(12.0, full) - jaw_open_weight(12.0)) < 1e-3
    span = shipped.identity[:, :f].reshape(k, -1).T
    means = []
    for seed in range(5):
        face, identity = random_subject(np.random.default_rng(seed), 0.0, full)
        assert identity["ict_modes"] == 100
        np.testing.assert_array_equal(identity["ict_weights"][:k], random_subject(np.random.default_rng(seed), 0.0)[1]["ict_weights"])
        offset = face[:f] - shipped.neutral[:f]
        weights = np.linalg.lstsq(span, offset.ravel(), rcond=None)[0]
        gap = np.linalg.norm(offset - (span @ weights).reshape(f, 3), axis=1)
        assert gap.mean() > 0.4 and gap.max() > 1.5  # mm
        means.append(gap.mean())
    assert np.mean(means) > 0.6


def test_load_ict_refuses_a_file_that_is_not_the_model(tmp_path):
    np.savez(tmp_path / "other.npz", neutral_mm=np.zeros((3, 3)))
    with pytest.raises(InputError, match="no identity_mm"):
        load_ict(tmp_path / "other.npz")
    with pytest.raises(InputError, match="cannot read"):
        load_ict(tmp_path / "absent.npz")


def test_a_face_is_the_neutral_plus_its_weighted_modes():
    model = load_ict()
    assert 0.97 <= model.identity_share and len(model.identity) <= 60
    w = np.random.default_rng(0).normal(size=len(model.identity))
    face = ict_face(model, w, {"jawOpen": 0.5})
    expected = model.neutral + np.einsum("k,kvc->vc", w, model.identity) + 0.5 * model.expressions[0]
    np.testing.assert_allclose(face, expected, atol=1e-9)
    np.testing.assert_array_equal(ict_face(model, np.zeros(0), {}), model.neutral)


def _landmark_gaps(face: np.ndarray) -> np.ndarray:
    """(K,) mm from each mapped template landmark's true position on an ICT face (V, 3) to the model's landmark."""
    model = load_ict()
    truth = template_truth(face)
    return np.linalg.norm(truth[list(MULTIPIE_TO_FACEMESH.values())] - face[model.landmarks[list(MULTIPIE_TO_FACEMESH)]], axis=1)


def test_the_template_lands_on_the_model_landmarks_of_the_neutral():
    gaps = _landmark_gaps(load_ict().neutral)
    assert gaps.max() < 3.0 and np.median(gaps) < 1.5  # mm; outer eye corners 2.6, the rest 0.6-1.5


def test_the_template_lands_on_the_model_landmarks_of_random_identities():
    """The correspondence is fixed on the topology: on other faces it still holds the landmarks (50
    identities: every pair within 3.4 mm, the outer eye corners the worst; medians up to 1.57 mm)."""
    model = load_ict()
    for seed in range(5):
        gaps = _landmark_gaps(ict_face(model, np.random.default_rng(seed).normal(size=len(model.identity)), {}))
        assert gaps.max() < 4.0 and np.median(gaps) < 1.7


def test_the_truth_lies_on_the_ict_face():
    model = load_ict()
    face = ict_face(model, np.random.default_rng(7).normal(size=len(model.identity)), {"jawOpen": 0.3})
    truth = template_truth(face)
    assert truth.shape == (len(load_template().vertices), 3)
    _, distance, _ = trimesh.proximity.closest_point(trimesh.Trimesh(face, model.triangles, process=False), truth)
    assert distance.max() < 1e-6  # mm
