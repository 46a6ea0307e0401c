"""An open mouth: the phantom's dropped jaw, the lips' opening read off the detected landmarks,
and the gate that keeps an oronasal cushion from being made for a jaw the template cannot follow."""

import json

import numpy as np
import pytest

from cpapfit.errors import QualityError
from cpapfit.io.capture import load_capture
from cpapfit.io.landmarks import landmarks_record, read_landmarks
from cpapfit.io.phantom import write_phantom
from cpapfit.landmarks.mouth import _gaps_in_depth, lips_apart_mm
from cpapfit.landmarks.types import Landmarks
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.synthetic.ict_phantom import make_ict_phantom
from cpapfit.synthetic.camera import FRAMED
from cpapfit.pipeline import align, assessed, design, place_template
from cpapfit.quality.gates import _mouth_gates
from cpapfit.thresholds import QualityParams
from cpapfit.scan import Intrinsics, Scan
from cpapfit.similarity import Similarity
from cpapfit.template import load_template

SEED = 101
OPEN_MM = 14.0  # well past the refusal (11 mm): the lips read 18 mm apart


def in_template_frame(ph) -> np.ndarray:
    """(N, 3) mm: the phantom's surface taken back out of its pose (the face before it was placed)."""
    pose = ph.pose
    return (ph.surface - pose["translation_mm"]) @ np.array(pose["rotation"]) + pose["template_centre_mm"]


def lips(surface: np.ndarray) -> float:
    """mm between the inner lips (landmarks 13, 14) of a (N, 3) surface."""
    return float(np.linalg.norm(surface[13] - surface[14]))


@pytest.fixture(scope="module")
def closed_and_open(tmp_path_factory):
    """Subject SEED, framed, with its mouth closed and opened (lower lip moved OPEN_MM): (phantom, capture scan) each."""
    out = []
    for mm in (0.0, OPEN_MM):
        ph = make_phantom(SEED, pose=FRAMED, mouth_open_mm=mm)
        folder = tmp_path_factory.mktemp(f"mouth{mm:g}")
        write_phantom(ph, folder)
        out.append((ph, load_capture(folder)))
    return out


def test_the_jaw_drops_below_the_mouth_and_nothing_moves_above_it(closed_and_open):
    (closed, _), (opened, _) = closed_and_open
    moved = np.linalg.norm(in_template_frame(opened) - in_template_frame(closed), axis=1)
    assert moved[14] == pytest.approx(OPEN_MM, rel=0.12)  # the lower lip (the face is scaled 0.9-1.1 after)
    assert lips(opened.surface) - lips(closed.surface) > 6.0
    t = load_template()
    above = t.vertices[:, 1] > t.landmarks[13, 1] + 20.0  # the nose and everything above it
    assert moved[above].max() < 1e-6
    assert moved[152] > 10.0  # the chin, further from the hinge than the lip
    assert (moved[t.regions["oronasal"].band] > 2.0).mean() > 0.25  # the seal's chin part goes with the jaw
    assert moved[t.regions["nasal"].band].max() < 1e-6


def test_the_detected_lips_measure_the_opening(closed_and_open):
    """MediaPipe's inner lips, taken to the depth of the fitted template's: a closed mouth reads
    under 3 mm (the shared real scans 0.7-1.2; the template's own lips, 4.8 mm apart, look closed),
    and opening it adds the opening, or up to 4 mm more (a wide mouth is over-read: the safe side)."""
    (closed, closed_scan), (opened, open_scan) = closed_and_open
    before, after = (align(scan).landmarks.lips_apart_mm for scan in (closed_scan, open_scan))
    assert before < 3.0
    assert -1.0 < (after - before) - (lips(opened.surface) - lips(closed.surface)) < 4.0  # mm


def test_an_open_mouth_refuses_the_oronasal_cushion_and_not_the_nasal(closed_and_open):
    _, (opened, scan) = closed_and_open
    placed = place_template(scan)
    with pytest.raises(QualityError, match="lips_apart_mm.*the mouth is open.*lips closed"):
        assessed(scan, "oronasal", placed)
    assert "lips_apart_mm" not in {g.code for g in assessed(scan, "nasal", placed).quality.gates}
    band = load_template().regions["nasal"].band
    assert np.linalg.norm(placed.registration.vertices[band] - opened.surface[band], axis=1).mean() < 1.0  # mm


def test_a_mesh_with_an_open_mouth_is_refused_too(closed_and_open):
    """The same open capture as a coloured mesh: the landmarks come from a render of it."""
    _, (_, capture) = closed_and_open
    colors = np.zeros((len(capture.vertices), 3), dtype=np.uint8)
    colors[capture.pixel_vertex[capture.valid]] = capture.image[capture.valid]
    mesh = Scan(capture.vertices, capture.faces, capture.normals, colors=colors)
    assert align(mesh).landmarks.path == "render"
    with pytest.raises(QualityError, match="lips_apart_mm"):
        design(mesh, "oronasal")


CAMERA = Intrinsics(100, 100, 600.0, 600.0, 50.0, 50.0)
PX_MM = 500.0 / 600.0  # one pixel's length at 500 mm


def test_an_ict_face_showing_its_teeth_reads_over_the_flag(tmp_path):
    """An ICT face (teeth, gums and tongue behind its lips; not the template), lower lip dropped
    12 mm, the inner lips ~14 mm apart: read over the flag (Face Mesh alone takes the teeth for lips
    and reads 4.5-11.7 mm on such faces); closed, under 3 mm."""
    read = []
    for mm in (0.0, 12.0):
        write_phantom(make_ict_phantom(7101, mouth_open_mm=mm), tmp_path / f"{mm:g}")
        read.append(align(load_capture(tmp_path / f"{mm:g}")).landmarks.lips_apart_mm)
    assert read[0] < 3.0 and read[1] > QualityParams().lips_apart_flag_mm


def test_the_gap_along_a_sloped_segment_between_ends_at_different_depths():
    """Depth rising 500 -> 540 mm down the image, no depth over rows 40-47: a diagonal segment crosses
    8 rows there, 8 sqrt(2) px, at ~519 mm: 9.8 mm, to within a pixel's length."""
    rows = np.arange(100, dtype=float)[:, None]
    depth = np.broadcast_to(500.0 + 0.5 * (rows - 10.0), (100, 100)).copy()
    depth[40:48, :] = np.nan
    anywhere, seen = _gaps_in_depth(np.array([[10.0, 10.0], [90.0, 90.0]]), np.array([500.0, 540.0]), depth, CAMERA)
    assert anywhere == pytest.approx(8 * np.sqrt(2.0) * 519.0 / 600.0, abs=np.sqrt(2.0) * 519.0 / 600.0)
    assert seen == 0.0  # a hole, not the inside of a mouth


@pytest.mark.parametrize("skin, rows, expected_px", [
    (np.nan, (40, 48), (8, 0)), (520.0, (30, 50), (20, 20)), (508.0, (30, 50), (20, 20)), (503.0, (30, 50), (0, 0)),
    (500.0, (30, 50), (0, 0)),
])
def test_the_gap_in_the_depth_is_the_longest_run_without_skin(skin, rows, expected_px):
    """Lips at 500 mm, a run of rows with no depth (a hole: not seen), depth 20 or 8 mm behind (the
    inside of the mouth, its teeth: seen), or 3 mm behind (still the lips): each run's length in mm
    is its pixels at 500 mm, to within a pixel."""
    depth = np.full((100, 100), 500.0)
    depth[rows[0]:rows[1], :] = skin
    gaps = _gaps_in_depth(np.array([[50.0, 10.0], [50.0, 90.0]]), np.array([500.0, 500.0]), depth, CAMERA)
    assert gaps == pytest.approx(np.multiply(expected_px, PX_MM), abs=PX_MM)


def test_lips_whose_fitted_depth_is_off_are_read_from_the_depth_at_their_ends():
    """The fitted template's lips 12 mm in front of the scan (a face seen from the side): the lips'
    own depth, 12 mm behind the template's line, is not read as an open mouth; a mouth 15 mm further
    behind still is."""
    depth = np.full((100, 100), 512.0)
    gaps = _gaps_in_depth(np.array([[50.0, 10.0], [50.0, 90.0]]), np.array([500.0, 500.0]), depth, CAMERA)
    assert gaps == (0.0, 0.0)
    depth[30:50, :] = 527.0
    assert _gaps_in_depth(np.array([[50.0, 10.0], [50.0, 90.0]]), np.array([500.0, 500.0]), depth, CAMERA)[1] == pytest.approx(
        20 * PX_MM, abs=PX_MM)


@pytest.mark.parametrize("ends, lips, inside, expected_px", [
    (488.0, 488.0, 496.0, 0),  # the scan's lips 12 mm in front of the fitted ones: 8 mm behind them is still lips
    (530.0, 530.0, 535.0, 0),  # the scan's lips 30 mm behind the fitted ones (a misplaced fit): 5 mm behind them is lips
    (530.0, 530.0, 560.0, 20),  # ... 30 mm behind them is a mouth
    (np.nan, 500.0, 520.0, 20),  # no depth at the segment's ends: the fitted lips' line
    (1500.0, 500.0, 520.0, 20),  # the background at the ends (a profile's edge): the fitted lips' line
])
def test_the_lips_line_is_behind_both_the_fitted_and_the_seen_lips(ends, lips, inside, expected_px):
    """Fitted lips at 500 mm; the segment's ends (rows 10 and 90) on depth `ends`, the lips between
    at `lips`, a mouth over rows 30-49 at `inside`: a point is inside the mouth only if 5 mm behind
    both the fitted lips' line and the line through the depth seen at the ends; ends without depth,
    or over 60 mm behind the fitted lips, give the fitted line alone."""
    depth = np.full((100, 100), lips)
    depth[:15, :] = depth[85:, :] = ends
    depth[30:50, :] = inside
    gaps = _gaps_in_depth(np.array([[50.0, 10.0], [50.0, 90.0]]), np.array([500.0, 500.0]), depth, CAMERA)
    assert gaps[1] == pytest.approx(expected_px * PX_MM, abs=PX_MM)


def test_an_end_off_the_image_takes_the_fitted_lips_depth():
    """The upper lip's end above the image, the image's top rows 15 mm behind the fitted lips (not
    the lips: clipped to the image, they would pull the lips' line back): the mouth (20 px, 12 mm
    behind the fitted lips) reads in full."""
    depth = np.full((100, 100), 500.0)
    depth[:3, :] = 515.0
    depth[30:50, :] = 512.0
    gaps = _gaps_in_depth(np.array([[50.0, -10.0], [50.0, 90.0]]), np.array([500.0, 500.0]), depth, CAMERA)
    assert gaps[1] == pytest.approx(20 * PX_MM, abs=PX_MM)


def test_surface_far_behind_the_lips_is_seen_through_a_hole_not_inside_a_mouth():
    """A run of depth 200 mm behind the lips (the back of a head through a slit) reads as a hole."""
    depth = np.full((100, 100), 500.0)
    depth[40:48, :] = 700.0
    gaps = _gaps_in_depth(np.array([[50.0, 10.0], [50.0, 90.0]]), np.array([500.0, 500.0]), depth, CAMERA)
    assert gaps == pytest.approx((8 * PX_MM, 0.0), abs=PX_MM)


@pytest.mark.parametrize("inside, expected_px", [(510.0, 20), (np.nan, 2)])
def test_teeth_behind_the_lips_outvote_face_mesh_and_a_hole_does_not(inside, expected_px):
    """Face Mesh's inner lips 2 px apart (teeth taken for lips) over a mouth 20 px open down the
    middle: teeth 10 mm behind the lips read the 20 px; the same run without depth (a hole) keeps
    the smaller reading, Face Mesh's."""
    template_landmarks = np.zeros((468, 3))
    template_landmarks[[0, 13, 14, 17], 1] = [-20.0, -1.0, 1.0, 20.0]  # mm: 10 px at 500 mm per 8.3 mm
    depth = np.full((100, 100), 500.0)
    depth[40:60, :] = inside
    uv = np.full((468, 2), 50.0)
    uv[[0, 13, 14, 17], 1] = [26.0, 49.0, 51.0, 74.0]
    fit = Similarity(1.0, np.eye(3), np.array([0.0, 0.0, 500.0]), np.ones(468), 0.0, 1)
    assert lips_apart_mm(uv, fit, template_landmarks, depth, CAMERA) == pytest.approx(expected_px * PX_MM, abs=PX_MM)


@pytest.mark.parametrize("mm, mask, expected", [
    (3.0, "oronasal", (False, False)), (9.0, "oronasal", (True, False)), (13.0, "oronasal", (True, True)),
    (13.0, "nasal", None), (np.nan, "oronasal", None),
])
def test_the_lips_gate_flags_then_refuses_oronasal_masks_only(mm, mask, expected):
    p = QualityParams()
    assert p.lips_apart_flag_mm < 9.0 < p.lips_apart_refuse_mm < 13.0
    landmarks = Landmarks(np.zeros((1, 3)), np.zeros(1, np.int64), np.ones(1), "image", lips_apart_mm=mm)
    gates = _mouth_gates(mask, landmarks, p)
    assert [(g.flag, g.refuse) for g in gates] == ([] if expected is None else [expected])


def test_a_landmarks_file_with_both_inner_lips_says_how_far_apart_they_are(tmp_path):
    t = load_template()
    index = [1, 4, 6, 13, 14, 152]
    points = t.vertices[index] / 1000.0 + [0.0, 0.0, 0.5]  # in metres
    (tmp_path / "lm.json").write_text(json.dumps({"points": points.tolist(), "template_index": index}))
    read = read_landmarks(tmp_path / "lm.json", "m", len(t.vertices))
    assert read.lips_apart_mm == pytest.approx(lips(t.vertices), abs=1e-9)
    assert landmarks_record(read)["lips_apart_mm"] == pytest.approx(lips(t.vertices), abs=0.01)
    (tmp_path / "few.json").write_text(json.dumps({"points": points[:4].tolist(), "template_index": index[:4]}))
    without = read_landmarks(tmp_path / "few.json", "m", len(t.vertices))
    assert np.isnan(without.lips_apart_mm) and landmarks_record(without)["lips_apart_mm"] is None
