"""Similarity alignment: the paper's alternating method agrees with Umeyama and shrugs off outliers."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cpapfit.similarity import _ls_pairwise_scale, fit_similarity, umeyama
from cpapfit.template import load_template


def angle_deg(a, b):
    return np.degrees(Rotation.from_matrix(a @ b.T).magnitude())


@pytest.fixture(scope="module")
def pair():
    """Template landmarks and a scan's: a known similarity plus 1.5 mm of landmark noise."""
    rng = np.random.default_rng(7)
    src = load_template().landmarks
    truth = dict(scale=1.08, rotation=Rotation.from_euler("xyz", [20, -35, 170], degrees=True).as_matrix(),
                 translation=np.array([30.0, -12.0, 480.0]))
    dst = truth["scale"] * src @ truth["rotation"].T + truth["translation"] + rng.normal(0, 1.5, src.shape)
    return src, dst, truth


def test_paper_method_matches_umeyama_on_clean_landmarks(pair):
    src, dst, _ = pair
    ours, closed = fit_similarity(src, dst, robust=False), umeyama(src, dst)
    assert ours.scale == pytest.approx(closed.scale, rel=1e-8)
    assert angle_deg(ours.rotation, closed.rotation) < 1e-6
    np.testing.assert_allclose(ours.translation, closed.translation, atol=1e-6)


def test_recovers_the_true_transform(pair):
    src, dst, truth = pair
    fit = fit_similarity(src, dst)
    assert fit.scale == pytest.approx(truth["scale"], rel=5e-3)  # 1.5 mm noise: scale error ~0.15 %
    assert angle_deg(fit.rotation, truth["rotation"]) < 0.2
    assert np.linalg.norm(fit.apply(src) - (truth["scale"] * src @ truth["rotation"].T + truth["translation"]), axis=1).max() < 0.5


def test_ten_percent_gross_outliers_change_nothing(pair):
    src, dst, _ = pair
    rng = np.random.default_rng(3)
    bad = rng.choice(len(dst), size=len(dst) // 10, replace=False)
    direction = rng.normal(size=(len(bad), 3))
    corrupted = dst.copy()
    corrupted[bad] += 30.0 * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    clean, robust = fit_similarity(src, dst), fit_similarity(src, corrupted)
    assert angle_deg(clean.rotation, robust.rotation) < 1.0
    moved = np.linalg.norm(clean.apply(src) - robust.apply(src), axis=1)
    assert moved.max() < 1.0  # mm, anywhere on the landmarks
    assert (robust.weights[bad] == 0).all()
    plain = umeyama(src, corrupted)  # for contrast: least squares is dragged off
    assert np.linalg.norm(clean.apply(src) - plain.apply(src), axis=1).max() > 1.0


def test_paper_initial_scale_is_least_squares_over_pairs(pair):
    src, dst, truth = pair
    assert _ls_pairwise_scale(src, dst) == pytest.approx(truth["scale"], rel=5e-3)
