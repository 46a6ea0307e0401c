"""The ICT face model shipped in the package, and the template mapped onto its topology."""

from importlib import resources

import numpy as np
import pytest
import trimesh

from cpapfit.ict import EXPRESSIONS, MULTIPIE_TO_FACEMESH, ict_face, load_ict, template_truth
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
