"""Synthetic subjects: ground truth consistent with the capture, deterministic, not the template."""

import json

import numpy as np
import pytest
import trimesh

from cpapfit.io import load_scan
from cpapfit.io.phantom import phantom_files
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.synthetic.camera import FRAMED, SensorModel
from cpapfit.template import load_template


@pytest.fixture(scope="module")
def truth(phantom1_dir):
    return trimesh.load(phantom1_dir / "ground_truth" / "surface.ply", process=False)


def test_capture_loads_back_as_a_scan(phantom1_dir, phantom1):
    scan = load_scan(phantom1_dir)
    assert scan.is_capture and scan.units == "mm"
    assert scan.valid.shape == (480, 640)
    assert len(scan.vertices) == scan.valid.sum() > 10_000
    assert np.array_equal(scan.image, phantom1.image)
    np.testing.assert_allclose(scan.intrinsics.matrix, phantom1.intrinsics.matrix, atol=1e-9)


def test_truth_surface_matches_valid_depth_within_the_noise_model(phantom1_dir, truth):
    """Cast each valid pixel's ray on the true surface (trimesh's own ray caster): the recorded
    depth differs from the true depth by the sensor noise model, and no more."""
    scan = load_scan(phantom1_dir)
    sensor = SensorModel()
    rays = scan.vertices / np.linalg.norm(scan.vertices, axis=1, keepdims=True)
    loc, ray_idx, _ = truth.ray.intersects_location(np.zeros_like(rays), rays, multiple_hits=False)
    assert len(ray_idx) == len(rays)  # every valid pixel sees the subject
    true_z = np.empty(len(rays))
    true_z[ray_idx] = loc[:, 2]
    residual = scan.vertices[:, 2] - true_z
    f = scan.intrinsics.fx
    sigma = np.sqrt(
        sensor.sigma_mm(true_z) ** 2
        + sensor.disparity_step_mm(true_z, f) ** 2 / 12.0
        + (1000.0 / sensor.depth_scale) ** 2 / 12.0
    )
    normalised = residual / sigma
    assert np.abs(normalised).max() < 5.5  # no pixel outside the noise model
    assert 0.9 < np.sqrt(np.mean(normalised**2)) < 1.1  # and the noise is as large as the model says
    assert abs(residual.mean()) < 0.05  # mm: no bias


def test_truth_is_the_template_vertex_order_and_landmarks(phantom1_dir, phantom1, truth):
    t = load_template()
    assert len(truth.vertices) == len(t.vertices)
    assert np.array_equal(truth.faces, t.faces)
    lm = json.loads((phantom1_dir / "ground_truth" / "landmarks.json").read_text())
    np.testing.assert_allclose(lm["points"], truth.vertices[:468], atol=1e-5)
    assert lm["template_index"] == list(range(468))


def test_subject_is_not_the_template(phantom1):
    """Same vertex order, different shape: after the best similarity fit, mm-scale differences remain."""
    t = load_template().vertices
    s = phantom1.surface
    a, b = t - t.mean(0), s - s.mean(0)
    u, sv, vt = np.linalg.svd(b.T @ a)
    r = u @ np.diag([1, 1, np.linalg.det(u @ vt)]) @ vt
    scale = sv.sum() / (a**2).sum()
    rms = np.sqrt(np.mean(np.sum((b - scale * a @ r.T) ** 2, axis=1)))
    assert rms > 1.0


def test_pose_and_distance_in_range():
    for seed in range(8):
        pose = make_phantom(seed).pose
        assert 350 <= pose["distance_mm"] <= 700
        assert abs(pose["yaw_deg"]) <= 25 and abs(pose["pitch_deg"]) <= 25 and abs(pose["roll_deg"]) <= 15


def test_a_framed_pose_is_the_same_face_turned_less_and_nearer_the_centre():
    """`FRAMED` bounds the pose (yaw/pitch 10 deg, roll 6 deg, 0.3 of the room off centre); the face,
    the camera and the distance are the seed's."""
    from cpapfit.rgbd import project

    for seed in range(4):
        wide, framed = make_phantom(seed), make_phantom(seed, pose=FRAMED)
        assert framed.identity == wide.identity and framed.intrinsics == wide.intrinsics
        p, q = wide.pose, framed.pose
        assert q["distance_mm"] == p["distance_mm"]
        for angle, bound in (("yaw_deg", 10), ("pitch_deg", 10), ("roll_deg", 6)):
            assert abs(q[angle]) <= bound and q[angle] == pytest.approx(p[angle] * bound / (25 if bound == 10 else 15))
        uv = project(framed.surface, framed.intrinsics)
        assert (uv >= 0).all() and (uv[:, 0] <= 639).all() and (uv[:, 1] <= 479).all()
        centre = np.array([framed.intrinsics.cx, framed.intrinsics.cy])
        assert np.linalg.norm(uv.mean(0) - centre) <= np.linalg.norm(project(wide.surface, wide.intrinsics).mean(0) - centre) + 1.0


def test_face_is_wholly_in_view(phantom1):
    from cpapfit.rgbd import project

    uv = project(phantom1.surface, phantom1.intrinsics)
    assert (uv >= 0).all() and (uv[:, 0] <= 639).all() and (uv[:, 1] <= 479).all()


def test_same_seed_same_bytes_other_seed_other_subject(phantom1):
    again = phantom_files(make_phantom(1))
    assert again == phantom_files(phantom1)
    assert phantom_files(make_phantom(2))["depth.png"] != again["depth.png"]


def test_sensor_effects_present(phantom1):
    """Holes and grazing-angle dropouts: some pixels on the subject have no depth."""
    from cpapfit.render import raycast

    on_face = raycast(phantom1.surface, phantom1.faces, phantom1.intrinsics).hit
    missing = on_face & (phantom1.depth_raw == 0)
    assert 0.01 < missing.sum() / on_face.sum() < 0.3
    assert (phantom1.depth_raw[~on_face] == 0).all()
