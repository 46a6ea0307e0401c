"""What stands in front of the face: a glasses frame on a synthetic subject, its area measured over
the registered face, and the gate that refuses a design made through it."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from cpapfit.align.nonrigid import Registration
from cpapfit.errors import QualityError
from cpapfit.quality.in_front import in_front_area_mm2
from cpapfit.io.capture import load_capture
from cpapfit.io.phantom import write_phantom
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.synthetic.camera import FRAMED
from cpapfit.pipeline import design
from cpapfit.thresholds import QualityParams
from cpapfit.template import load_template

SEED = 102


@pytest.fixture(scope="module")
def bare_and_worn():
    return [make_phantom(SEED, pose=FRAMED, glasses=worn) for worn in (False, True)]


def test_glasses_are_seen_but_are_not_the_face(bare_and_worn):
    """The truth is the face under the frame; the camera sees the frame: nearer depth, dark pixels."""
    bare, worn = bare_and_worn
    assert np.array_equal(bare.surface, worn.surface)
    nearer = (worn.depth_raw > 0) & ((bare.depth_raw == 0) | (worn.depth_raw.astype(float) < bare.depth_raw.astype(float) - 30))  # 3 mm
    assert nearer.sum() > 200  # pixels of frame in front of the skin
    assert worn.image[nearer].mean() < 0.6 * bare.image[nearer].mean()


def test_a_design_through_glasses_is_refused_with_the_reason(bare_and_worn, tmp_path):
    _, worn = bare_and_worn
    write_phantom(worn, tmp_path)
    with pytest.raises(QualityError, match=r"in_front_mm2.*mm² of the scan stands over 5 mm in front.*glasses"):
        design(load_capture(tmp_path), "nasal")


def test_a_clean_face_has_nothing_in_front(designed):
    _, d = designed
    assert {g.code: g.value for g in d.quality.gates}["in_front_mm2"] == 0.0


@pytest.mark.parametrize("height_mm, expected_mm2", [(10.0, 100.0), (3.0, 0.0), (-10.0, 0.0)])
def test_the_area_in_front_is_the_plate_standing_out_past_5_mm(height_mm, expected_mm2):
    """The template as its own registration, scanned with a 10 x 10 mm plate (1 mm grid) held
    `height_mm` out from the nose tip along its normal: only a plate past 5 mm counts, its area."""
    t = load_template()
    normal = np.asarray(t.mesh().vertex_normals)[4]
    u = np.cross(normal, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    grid = np.stack(np.meshgrid(np.arange(-4.5, 5.0), np.arange(-4.5, 5.0)), axis=-1).reshape(-1, 2)
    plate = t.vertices[4] + height_mm * normal + grid[:, :1] * u + grid[:, 1:] * v
    points = np.vstack([t.vertices, plate])
    registration = Registration(t.vertices, np.zeros(len(t.vertices)), np.ones(len(t.vertices), dtype=bool))
    area = in_front_area_mm2(points, cKDTree(points), registration, t)
    assert area == pytest.approx(expected_mm2, abs=5.0)
    assert QualityParams().in_front_flag_mm2 < 100.0 - 5.0  # such a plate is flagged


def test_a_lone_point_far_out_is_noise_not_a_surface():
    """A depth camera's noise spike: one scan point 10 mm out from the nose tip counts nothing."""
    t = load_template()
    spike = t.vertices[4] + 10.0 * np.asarray(t.mesh().vertex_normals)[4]
    points = np.vstack([t.vertices, spike])
    registration = Registration(t.vertices, np.zeros(len(t.vertices)), np.ones(len(t.vertices), dtype=bool))
    assert in_front_area_mm2(points, cKDTree(points), registration, t) == 0.0
