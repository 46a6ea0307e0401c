"""Quality gates on synthetic subjects made to trip them, and the design run twice: the same bytes,
and no network (sockets blocked)."""

import contextlib
import dataclasses
import io
import json
import multiprocessing
import os
import subprocess
import sys
import threading
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest
import trimesh

from records import DATE_EPOCH, written
from cpapfit.cli import main
from cpapfit.io import load_scan
from cpapfit.io.landmarks import user_landmarks
from cpapfit.pipeline import Placement, assessed, place_template
from cpapfit.outputs import report_files
from cpapfit.jobs import worker
from cpapfit.work import at_once
from cpapfit.io.capture import capture_files
from cpapfit.io.write import json_bytes, record_bytes, write_files
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.synthetic.camera import SensorModel
from cpapfit.synthetic.defects import with_colour_shift, with_holes
from cpapfit.evaluation.gap import RimGap
from cpapfit.errors import QualityError
from cpapfit.quality.proportions import proportions
from cpapfit.loops import longest_run
from cpapfit.quality.gates import assess, require_quality
from cpapfit.thresholds import DISAGREE_MM, QualityParams
from cpapfit.template import load_template

GATES = QualityParams()


def run_design(*argv) -> tuple[int, str]:
    """`cpapfit design` in-process: (exit code, stderr)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["design", *map(str, argv), "--quiet"])
    return code, err.getvalue()


OFFLINE_DESIGN = """
import os, socket, ssl, sys  # ssl subclasses socket.socket: imported before that is replaced
def refuse(*args, **kwargs):
    os.write(2, b"network attempt\\n")  # straight to stderr, from the forked worker too, caught or not
    raise OSError("network use during a cpapfit run")
for name in ("socket", "create_connection", "getaddrinfo", "socketpair"):
    setattr(socket, name, refuse)
import cpapfit.jobs
cpapfit.jobs._idle_core = lambda: True
from cpapfit.cli import main
sys.exit(main({argv!r}))
"""


@pytest.fixture(scope="module")
def twice(nasal1, tmp_path_factory):
    """Seed 1's nasal design twice: through the Python API (`nasal1`), saved; and by `cpapfit design`
    as its own process (fresh and single-threaded, so the stock sizes and the pictures are made in its
    forked worker even on a busy machine) with every way to open a socket refused.
    {"plain"|"offline": (code, stderr, folder)}."""
    offline = tmp_path_factory.mktemp("offline")
    argv = ["design", str(nasal1.scan.source), "--stock", "gauge", "--out", str(offline), "--quiet"]
    env = {**os.environ, "SOURCE_DATE_EPOCH": DATE_EPOCH}  # the run date, to the minute, is on the report
    run = subprocess.run([sys.executable, "-c", OFFLINE_DESIGN.format(argv=argv)], env=env, capture_output=True, text=True)
    return {"plain": (0, "", nasal1.save(tmp_path_factory.mktemp("plain") / "design")), "offline": (run.returncode, run.stderr, offline)}


def design_bytes(folder: Path) -> dict:
    """{file name: bytes} of a design folder; manifest.json as its record less the units asked for
    (the command line records what --units said, "auto"; a Python design the units its scan was read in)."""
    files = {p.name: p.read_bytes() for p in sorted(folder.iterdir())}
    manifest = json.loads(files.pop("manifest.json"))
    manifest["parameters"].pop("units")
    return files | {"manifest.json": manifest}


def test_the_same_input_gives_the_same_bytes(twice):
    """The Python API in this process and the command in its own, with its worker: the same bytes."""
    files = {name: design_bytes(out) for name, (_, _, out) in twice.items()}
    assert len(files["plain"]) >= 8 and files["plain"].keys() == files["offline"].keys()
    for name, data in files["plain"].items():
        assert data == files["offline"][name], name


def test_a_records_last_bits_do_not_change_its_bytes():
    """Two stock figures of one design made in two processes (OpenBLAS's last bits differing with the
    arrays' alignment): the same record bytes, each figure within 5e-10 of itself, as a float64 in
    a tuple too, NaN kept; files read back as input (a capture's intrinsics) keep every bit."""
    made = {"leak_l_min": 1074.1747658303243, "peak": (np.float64(4.821079657835299), 2), "gap": np.nan}
    again = {"leak_l_min": 1074.174765830324, "peak": (np.float64(4.821079657835297), 2), "gap": np.nan}
    assert record_bytes(made) == record_bytes(again) and json_bytes(made) != json_bytes(again)
    back = json.loads(record_bytes(made))
    assert back["leak_l_min"] == pytest.approx(made["leak_l_min"], rel=5e-10, abs=0.0) and back["peak"][1] == 2 and np.isnan(back["gap"])


def test_a_design_needs_no_network(twice):
    code, err, out = twice["offline"]
    assert code == 0, err
    assert "network attempt" not in err
    assert (out / "cushion.stl").stat().st_size > 0


def test_a_clean_subject_trips_no_gate(twice):
    code, err, out = twice["offline"]
    fit = written(out / "fit.json")
    assert code == 0 and fit["rescan_advised"] is False and fit["warnings"] == []
    q = fit["quality"]
    assert q["coverage"] > GATES.coverage_flag and q["hole_mm"] < GATES.hole_flag_mm
    assert q["residual_mm"] < GATES.residual_flag_mm and q["landmarks_mm"] < GATES.landmarks_flag_mm
    assert q["rim_gap_mm"] < GATES.rim_gap_flag_mm and q["landmark_spread_mm"] < GATES.detected_spread_flag_mm
    assert "rescan advised" not in err


def test_a_clean_subject_has_its_true_proportions(twice, phantom1):
    """Size and depth for breadth as the generator made them (its overall scale, and the face's width
    and height stretched; its local changes of nose and chin move the depth ratio by up to ~0.07)."""
    q = written(twice["plain"][2] / "fit.json")["quality"]
    p = phantom1.identity
    breadth = np.sqrt(p["face_width"] * p["face_height"])
    assert q["face_size"] == pytest.approx(p["scale"] * breadth, abs=0.03)
    assert q["depth_ratio"] == pytest.approx(1.0 / breadth, abs=0.08)


@dataclasses.dataclass(frozen=True)
class Judged:
    """What the quality gates make of a subject's capture: the codes of the gates flagged, their
    messages (one string), the fit.json quality values, and the template's `Placement`."""

    codes: list[str]
    messages: str
    quality: dict
    placed: Placement


def judged_gates(tmp_path, ph, mask: str = "nasal", landmarks: Path | None = None) -> Judged:
    """Place the template on a subject's capture (`landmarks`: a user file) and judge the scan for
    `mask` as `design` does before the cushion is made (only the gates are read: the design after
    them does not change them); it must be flagged."""
    write_files(tmp_path / "capture", capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
    scan = load_scan(tmp_path / "capture")
    placed = place_template(scan, user_landmarks(landmarks, scan))
    record = assessed(scan, mask, placed).quality.record()
    assert record["rescan_advised"] is True, record
    return Judged([w["code"] for w in record["warnings"]], " ".join(w["message"] for w in record["warnings"]), record["quality"], placed)


def with_intrinsics(ph, focal: float = 1.0):
    """The subject's capture with its focal length stated `focal` times too long."""
    return dataclasses.replace(ph, intrinsics=dataclasses.replace(ph.intrinsics, fx=ph.intrinsics.fx * focal, fy=ph.intrinsics.fy * focal))


def test_a_misstated_focal_length_is_flagged(tmp_path, phantom1, twice):
    """Intrinsics whose focal length is 1.3 times too long (another camera's, or another resolution's)
    make the face 1.3 times too narrow and short for its depth, and the mask as much too small; the
    shape fits as well as ever, so only the face's proportions tell: flagged, saying what to check."""
    clean = written(twice["plain"][2] / "fit.json")["quality"]
    judged = judged_gates(tmp_path, with_intrinsics(phantom1, 1.3))
    codes, err, q = judged.codes, judged.messages, judged.quality
    assert codes and set(codes) <= {"depth_ratio", "face_size"} and "intrinsics (fx, fy)" in err, err
    assert q["face_size"] / clean["face_size"] == pytest.approx(1 / 1.3, abs=0.03)
    assert 1.15 < q["depth_ratio"] / clean["depth_ratio"] < 1.3


def test_a_misstated_depth_scale_is_flagged(tmp_path, phantom1):
    """A depth scale 1.35 times too large: the whole face, and the mask, 1.35 times too small
    (in proportion: the shape alone cannot tell), smaller than adults' faces are: flagged."""
    stated = dataclasses.replace(phantom1, sensor=dataclasses.replace(phantom1.sensor, depth_scale=phantom1.sensor.depth_scale * 1.35))
    judged = judged_gates(tmp_path, stated)
    codes, err, q = judged.codes, judged.messages, judged.quality
    assert codes == ["face_size"] and "check the capture's depth scale" in err, err
    p = phantom1.identity
    assert q["face_size"] == pytest.approx(p["scale"] * np.sqrt(p["face_width"] * p["face_height"]) / 1.35, abs=0.03)


def test_holes_under_the_seal_are_flagged(tmp_path, phantom1):
    """A hole over a third of the seal curve (~45 mm, one stretch): the whole command designs it
    (neither the gates nor the rim's share over scanned skin refuse it), flagged, saying so."""
    curve = load_template().regions["nasal"].curve
    ph = with_holes(phantom1, curve[: len(curve) // 3], 0.95, radius_px=(8.0, 10.0))
    write_files(tmp_path / "capture", capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
    code, err = run_design(tmp_path / "capture", "--stock", "none", "--mask", "nasal", "--out", tmp_path / "out")
    fit = written(tmp_path / "out" / "fit.json")
    assert code == 0 and fit["rescan_advised"] is True and "rescan advised" in err, err
    assert "hole_mm" in [w["code"] for w in fit["warnings"]] and fit["custom"]["rim_covered_fraction"] < 1.0, err


def test_a_noisy_scan_is_flagged(tmp_path):
    judged = judged_gates(tmp_path, make_phantom(1, SensorModel(noise_mm_at_500=3.0)))
    assert "residual_mm" in judged.codes, judged.messages


def test_landmarks_off_the_skin_are_flagged(tmp_path, phantom1):
    """The true landmarks, 1.5 mm in front of the skin (a file from another session)."""
    idx = np.arange(0, 468, 3)
    off = phantom1.landmarks[idx] - [0.0, 0.0, 1.5]  # towards the camera
    (tmp_path / "lm.json").write_text(json.dumps({"points": off.tolist(), "template_index": idx.tolist()}))
    judged = judged_gates(tmp_path, phantom1, landmarks=tmp_path / "lm.json")
    assert judged.codes == ["landmarks_mm"], judged.messages


def test_landmarks_off_along_the_skin_are_flagged_and_not_trusted(tmp_path, phantom1):
    """The true landmarks moved 4 mm (per axis) and put back on the skin (a careless file): on the
    skin, so the landmarks_mm gate passes them; far from their places on the face, so they are used
    at the detected landmarks' weight and the scan is flagged for their spread alone."""
    idx = np.arange(0, 468, 3)
    truth = trimesh.Trimesh(phantom1.surface, phantom1.faces, process=False)
    moved = phantom1.landmarks[idx] + np.random.default_rng(0).normal(0.0, 4.0, (len(idx), 3))
    (tmp_path / "lm.json").write_text(json.dumps({"points": truth.nearest.on_surface(moved)[0].tolist(), "template_index": idx.tolist()}))
    judged = judged_gates(tmp_path, phantom1, landmarks=tmp_path / "lm.json")
    assert judged.codes == ["landmark_spread_mm"], judged.messages
    assert judged.placed.registration.landmark_factor == pytest.approx(0.1)
    assert judged.quality["landmark_spread_mm"] > GATES.landmark_spread_flag_mm


def test_a_colour_image_shifted_from_its_depth_is_flagged(tmp_path, phantom1):
    """Colour 12 px (~12 mm) to the side of the depth, a capture not registered: the detected
    landmarks are lifted onto the wrong skin and drag the seal ~2 mm along it. Their spread from
    the face the geometry gives (10.4 mm against 2.3 unshifted; 8.4 before the mirror term, which
    holds the face nearer the truth) flags it, saying why: past 7 mm as a spread, past 10 mm by
    dropping them for the face's shape alone (landmark-free)."""
    judged = judged_gates(tmp_path, with_colour_shift(phantom1, 12))
    assert {"landmark_spread_mm", "landmark_free"} & set(judged.codes), judged.messages
    assert "colour image may not line up with the depth" in judged.messages, judged.messages
    assert judged.quality.get("landmark_spread_mm", np.inf) > GATES.detected_spread_flag_mm  # none recorded once they are dropped


def test_a_colour_image_far_from_its_depth_is_refused_for_the_disagreement(tmp_path, phantom1):
    """Colour 32 px (~3 cm) to the side: the face MediaPipe finds fails the face check, and the face's
    shape alone places the mask region far from it. One of the two is on the wrong part of the face
    and nothing tells which (on an ICT subject the shape put a nasal cushion on the lips), so the scan
    is refused, saying how far apart they are, and nothing is written."""
    ph = with_colour_shift(phantom1, 32)
    write_files(tmp_path / "capture", capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
    code, err = run_design(tmp_path / "capture", "--out", tmp_path / "out")
    assert code == 2 and "the face found by image (which failed the face check)" in err, err
    apart = float(err.split("place the mask region ")[1].split(" mm apart")[0])
    assert apart > DISAGREE_MM, err
    assert not (tmp_path / "out").exists()


def test_a_capture_without_colour_is_designed_from_the_shape_and_flagged(tmp_path, phantom1):
    """No colour image: no face to detect, the template placed by the shape alone; flagged, since on a
    real face that can put the seal a few mm from where landmarks put it."""
    write_files(tmp_path / "capture", capture_files(phantom1.image, phantom1.depth_raw, phantom1.intrinsics, phantom1.sensor.depth_scale))
    (tmp_path / "capture" / "color.png").unlink()
    code, err = run_design(tmp_path / "capture", "--stock", "none", "--out", tmp_path / "out")
    fit = written(tmp_path / "out" / "fit.json")
    assert code == 0 and fit["landmarks"]["path"] == "fallback", err
    assert [w["code"] for w in fit["warnings"]] == ["landmark_free"] and "no face was detected" in err
    assert "the capture has no colour image: add color.png" in err


def shape_of(d):
    """The proportions of a design's registered face."""
    return proportions(load_template().vertices, d.alignment.similarity, d.registration)


def test_a_rim_off_the_skin_is_refused_and_one_noisy_sample_is_not(designed, tmp_path):
    """Where the template missed the face the cushion's rim stands off the scanned skin (a mesh once
    gave 9 mm over 60 mm of rim): refused. One noisy sample 3 mm off is not a stretch of rim."""
    ph, d = designed
    write_files(tmp_path, capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
    scan = load_scan(tmp_path)
    assert d.quality.record()["quality"]["rim_gap_mm"] < GATES.rim_gap_flag_mm
    off_skin = RimGap(np.where(np.arange(256) < 60, 9.0, d.rim.gap), d.rim.covered | (np.arange(256) < 60))
    with pytest.raises(QualityError, match="rim stands up to 9.0 mm off the scanned skin"):
        require_quality(assess(scan, d.alignment.landmarks, d.registration, d.contact, off_skin, shape_of(d)))
    spike = np.zeros(256)
    spike[100] = 3.0
    assert RimGap(spike, np.ones(256, dtype=bool)).worst_stretch_mm() == 0.0
    off = np.where((np.arange(256) >= 40) & (np.arange(256) < 100), 9.0, 0.2)
    assert RimGap(off, np.ones(256, dtype=bool)).worst_stretch_mm() == pytest.approx(9.0)
    assert RimGap(off, np.arange(256) < 40).worst_stretch_mm() == pytest.approx(0.2)  # over no scan data: not measured


def test_longest_hole_wraps_around_the_seal():
    bad = np.array([1, 1, 0, 0, 1, 0, 1, 1, 1], dtype=bool)
    count = lambda flag: longest_run(flag, np.ones(len(flag)))[0]  # noqa: E731
    assert count(bad) == 5 and count(~bad) == 2
    assert count(np.ones(4, bool)) == 4 and count(np.zeros(4, bool)) == 0


def test_pictures_drawn_in_a_worker_process_are_the_same_bytes(nasal1, monkeypatch):
    """The report drawn with its design pictures in a second process (as `cpapfit design` does) is
    the report `nasal1` drew in one, every picture and the page (a spawned worker: this test process
    already runs other threads). The assembled mask's and the evaluation's pictures and the page are
    drawn here a second time."""
    monkeypatch.setenv("SOURCE_DATE_EPOCH", DATE_EPOCH)  # the run date, to the minute, is on the page
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        drawn = report_files(nasal1.design, nasal1.scan, nasal1.files, pool.submit)
    assert drawn == {name: data for name, data in nasal1.files.items() if name.endswith(".png") or name == "report.html"}


def test_no_worker_is_forked_from_a_process_running_threads():
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()
    try:
        with worker(True) as submit:
            assert submit is at_once
    finally:
        stop.set()
        thread.join()


def test_the_advice_blames_a_meshs_colours_only_when_the_landmarks_were_found_on_them():
    """Detected landmarks far from the geometry on a coloured mesh: found on its coloured renders,
    the advice names the colours; found on its renders drawn without them, the shaded render."""
    from cpapfit.landmarks.types import WITHOUT_COLOURS, Landmarks
    from cpapfit.quality.gates import _spread_gate
    from cpapfit.scan import Scan

    box = trimesh.creation.box((100, 100, 100))
    scan = Scan(box.vertices, box.faces, box.vertex_normals, colors=np.full((len(box.vertices), 3), 200, dtype=np.uint8))
    found = Landmarks(np.zeros((3, 3)), np.arange(3), np.ones(3), "render", note="render view 0, rotation 0 deg")
    coloured = _spread_gate(scan, found, 12.0, QualityParams())
    bare = _spread_gate(scan, dataclasses.replace(found, note=found.note + "; on renders" + WITHOUT_COLOURS), 12.0, QualityParams())
    assert coloured.flag and "colours may be misplaced" in coloured.message
    assert bare.flag and "colours" not in bare.message and "shaded render" in bare.message


def test_a_decimated_meshs_sparse_flat_parts_have_scan_data_and_its_holes_have_none():
    """The plane z = 0 sampled every 1 mm, but every 8 mm over a 24 mm square (a decimated mesh's
    vertices are sparse where the face is flat), and with no points over a 20 mm disc (a hole):
    the coverage and hole gates count points 6 mm from the sparse square's centre as over scan data
    (by the scan's median spacing, 1 of 12 was), and points within 7 mm of the hole's centre as over
    none."""
    from scipy.spatial import cKDTree

    from cpapfit.quality.gates import _has_data
    from cpapfit.scan import Scan

    grid = np.stack(np.meshgrid(np.arange(-60, 61, 1.0), np.arange(-40, 41, 1.0)), -1).reshape(-1, 2)
    sparse = (np.abs(grid - [-30, 0]) < 12).all(axis=1)
    grid = grid[(~sparse | (grid % 8 == 0).all(axis=1)) & (np.linalg.norm(grid - [30, 0], axis=1) > 10)]
    vertices = np.column_stack([grid, np.zeros(len(grid))])
    mesh, tree = Scan(vertices, np.zeros((0, 3), dtype=np.int64), np.tile([0.0, 0.0, 1.0], (len(grid), 1))), cKDTree(vertices)
    t = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    over_sparse = np.column_stack([-30 + 6 * np.cos(t), 6 * np.sin(t), np.zeros(12)])
    over_hole = np.column_stack([30 + 7 * np.cos(t), 7 * np.sin(t), np.zeros(12)])
    assert _has_data(mesh, tree, over_sparse, QualityParams().near_mm).all()
    assert not _has_data(mesh, tree, over_hole, QualityParams().near_mm).any()
    assert not _has_data(mesh, tree, np.array([[30.0, 0.0, 0.0]]), QualityParams().near_mm).any()


def test_a_depth_image_riddled_with_small_holes_has_data_only_near_its_pixels():
    """A depth image at 1 mm pitch with only 2 x 2 pixel islands every 6 pixels left (the rest holes):
    the middle of the 4 x 4 hole between four islands, 3.5 mm from the nearest pixel, has no scan
    data (by the islands' own one-sided neighbourhoods it would: their local spacing reads 3.7 mm)."""
    from scipy.spatial import cKDTree

    from cpapfit.quality.gates import _has_data
    from cpapfit.scan import Intrinsics, Scan

    grid = np.stack(np.meshgrid(np.arange(-60, 61, 1.0), np.arange(-40, 41, 1.0)), -1).reshape(-1, 2)
    valid = ((grid % 6) < 2).all(axis=1)
    grid = grid[valid]
    vertices = np.column_stack([grid, np.zeros(len(grid))])
    pixel_vertex = np.full(len(valid), -1)
    pixel_vertex[valid] = np.arange(len(grid))
    valid = valid.reshape(81, 121)
    capture = Scan(vertices, np.zeros((0, 3), dtype=np.int64), np.tile([0.0, 0.0, 1.0], (len(grid), 1)), depth=np.where(valid, 0.0, np.nan),
                   valid=valid, pixel_vertex=pixel_vertex.reshape(81, 121), intrinsics=Intrinsics(121, 81, 1.0, 1.0, 60.0, 40.0))
    middles = np.array([[3.5 + 6 * i, 3.5 + 6 * j, 0.0] for i in range(-5, 5) for j in range(-5, 5)])
    assert not _has_data(capture, cKDTree(vertices), middles, QualityParams().near_mm).any()
