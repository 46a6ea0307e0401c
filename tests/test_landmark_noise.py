"""Noise on the detected landmarks (`LandmarkNoise`, for robustness studies): along the skin,
reproducible from its seed, the similarity refitted to it."""

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from cpapfit.align.nonrigid import vertex_normals
from cpapfit.landmarks.detect import Detection
from cpapfit.landmarks.noise import LandmarkNoise, with_noise
from cpapfit.landmarks.types import Landmarks
from cpapfit.scan import Scan
from cpapfit.similarity import fit_similarity
from cpapfit.template import N_LANDMARKS, load_template

TEMPLATE = load_template()
TURN = Rotation.from_euler("yxz", [20.0, -10.0, 5.0], degrees=True).as_matrix()
SCALE, SHIFT = 1.08, np.array([12.0, -30.0, 450.0])


@pytest.fixture(scope="module")
def found() -> tuple[Scan, Detection]:
    """The template's surface turned, scaled and moved as a mesh scan (mm), and a detection of its 468 landmarks exactly."""
    vertices = SCALE * TEMPLATE.vertices @ TURN.T + SHIFT
    scan = Scan(vertices, TEMPLATE.faces, vertex_normals(vertices, TEMPLATE.faces))
    index = np.arange(N_LANDMARKS)
    fit = fit_similarity(TEMPLATE.vertices[index], vertices[index])
    return scan, Detection(Landmarks(vertices[index], index, fit.weights, "render"), fit, N_LANDMARKS)


def test_landmark_noise_moves_points_along_the_skin_and_refits_the_similarity(found):
    scan, exact = found
    noisy = with_noise(exact, scan, TEMPLATE, LandmarkNoise(sigma_mm=2.0, seed=3))
    points = noisy.landmarks.points
    assert cKDTree(scan.vertices).query(points)[0].max() == 0.0  # on the skin: scan vertices
    moved = np.linalg.norm(points - exact.landmarks.points, axis=1)
    assert 1.5 <= moved.mean() <= 3.5 and np.median(moved) > 1.0  # sigma 2 mm per axis, less the part off the skin
    assert np.array_equal(noisy.landmarks.template_index, exact.landmarks.template_index)
    assert noisy.similarity.scale == pytest.approx(SCALE, rel=0.01)  # 468 points: the noise averages out
    assert np.abs(noisy.similarity.rotation - TURN).max() < 0.005
    assert np.array_equal(noisy.landmarks.confidence, noisy.similarity.weights)
    assert noisy.landmarks.note.endswith("noise of 2 mm added (seed 3)")  # a design made with it says so
    assert np.array_equal(with_noise(exact, scan, TEMPLATE, LandmarkNoise(2.0, 3)).landmarks.points, points)  # its seed's
    assert not np.array_equal(with_noise(exact, scan, TEMPLATE, LandmarkNoise(2.0, 4)).landmarks.points, points)
    assert with_noise(exact, scan, TEMPLATE, LandmarkNoise()) is exact  # none by default
