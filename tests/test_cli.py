"""The command line: the demo runs, and bad input gets one clear line, exit code 2, no output."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
import trimesh
from PIL import Image

from records import written
from cpapfit.cushion.generic import template_cushion
from cpapfit.cushion.nurbs import MEMBRANE_ROWS
from cpapfit.fabrication.files import SolidError


def assert_one_line_error(code, out, err, *words):
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cpapfit: error:"), err
    assert "Traceback" not in err
    for word in words:
        assert word in lines[0], lines[0]


@pytest.mark.slow
def test_demo_runs_every_stage_and_points_to_the_report(cli, tmp_path):
    code, out, err = cli("demo", "--out", tmp_path)
    assert code == 0
    assert "RGB-D capture 640x480" in out
    stages = [line.split()[0] for line in out.split("\nreport: ")[0].splitlines() if line.startswith("  ")]
    assert stages == ["scan", "template", "landmarks", "similarity", "nonrigid", "contact", "cushion", "export", "evaluate", "report"]
    assert "by image" in out and "safe window" in out
    assert (tmp_path / "subject" / "depth.png").is_file()
    assert Image.open(tmp_path / "template_regions.png").size == (640, 480)
    assert (tmp_path / "design" / "cushion.stl").is_file() and (tmp_path / "design" / "registration_residual.png").is_file()
    report = tmp_path / "design" / "report.html"
    assert f"report: {report}" in out and "custom at" in out and "stock " in out and "L/min" in out
    page = report.read_text()
    assert 'data-key="headgear_force_n"' in page and 'data-key="stock.pressure_cv"' in page


def test_phantom_command_writes_a_capture(cli, tmp_path):
    code, _, err = cli("phantom", "--seed", 3, "--out", tmp_path / "p")
    assert code == 0 and "6 files" in err
    code, out, _ = cli("inspect", tmp_path / "p")
    assert code == 0 and "RGB-D capture" in out


def test_missing_file(cli, tmp_path):
    assert_one_line_error(*cli("inspect", tmp_path / "nope.ply"), "no such file")


def test_empty_file(cli, tmp_path):
    (tmp_path / "empty.ply").write_bytes(b"")
    assert_one_line_error(*cli("inspect", tmp_path / "empty.ply"), "empty")


def test_truncated_ply(cli, tmp_path, phantom1):
    whole = trimesh.Trimesh(phantom1.surface, phantom1.faces).export(file_type="ply")
    (tmp_path / "cut.ply").write_bytes(whole[: len(whole) // 3])
    assert_one_line_error(*cli("inspect", tmp_path / "cut.ply"), "cut.ply")


def test_garbage_with_mesh_extension(cli, tmp_path):
    (tmp_path / "junk.stl").write_bytes(np.random.default_rng(0).bytes(3000))
    assert_one_line_error(*cli("inspect", tmp_path / "junk.stl"), "junk.stl")


def test_nan_vertices(cli, tmp_path, phantom1):
    v = phantom1.surface.copy()
    v[100] = np.nan
    (tmp_path / "nan.ply").write_bytes(trimesh.Trimesh(v, phantom1.faces, process=False).export(file_type="ply"))
    assert_one_line_error(*cli("inspect", tmp_path / "nan.ply"), "NaN")


def test_wrong_stated_units(cli, tmp_path, phantom1):
    trimesh.Trimesh(phantom1.surface / 1000, phantom1.faces).export(tmp_path / "m.ply")
    assert_one_line_error(*cli("inspect", tmp_path / "m.ply", "--units", "mm"), "check the unit")


@pytest.fixture
def capture(tmp_path, phantom1_dir):
    folder = tmp_path / "capture"
    shutil.copytree(phantom1_dir, folder)
    return folder


def test_depth_of_zeros(cli, capture):
    Image.fromarray(np.zeros((480, 640), dtype=np.uint16)).save(capture / "depth.png")
    assert_one_line_error(*cli("inspect", capture), "valid")


def test_intrinsics_that_do_not_match_the_image(cli, capture):
    intr = json.loads((capture / "intrinsics.json").read_text())
    intr["width"], intr["height"] = 1280, 720
    (capture / "intrinsics.json").write_text(json.dumps(intr))
    assert_one_line_error(*cli("inspect", capture), "1280x720")


def test_colour_and_depth_of_different_sizes(cli, capture):
    Image.open(capture / "color.png").resize((320, 240)).save(capture / "color.png")
    assert_one_line_error(*cli("inspect", capture), "register")


@pytest.mark.parametrize("text", ["", "{", '{"width": 640}', '{"width": 640, "height": 480, "intrinsic_matrix": [0,0,0,0,0,0,0,0,1]}'])
def test_nonsense_intrinsics(cli, capture, text):
    (capture / "intrinsics.json").write_text(text)
    assert_one_line_error(*cli("inspect", capture), "intrinsics")


def test_missing_intrinsics_and_truncated_depth(cli, capture):
    data = (capture / "depth.png").read_bytes()
    (capture / "depth.png").write_bytes(data[: len(data) // 2])
    assert_one_line_error(*cli("inspect", capture), "depth.png")
    (capture / "intrinsics.json").unlink()
    assert_one_line_error(*cli("inspect", capture), "intrinsics.json")


@pytest.mark.parametrize("thicker", ["wall", "membrane"])
def test_a_cushion_failing_the_printability_checks_writes_nothing(cli, tmp_path, phantom1_dir, placed1, monkeypatch, thicker):
    """Demand a wall (or membrane) thicker than the design can give: the check refuses, and no file is written."""
    import cpapfit.pipeline as pipeline
    from cpapfit.fabrication.files import check_solid

    def demanding(mesh, wall, set_wall, name, membrane):
        if thicker == "wall":
            return check_solid(mesh, wall, 2 * wall, name, membrane)
        return check_solid(mesh, wall, set_wall, name, (membrane[0], membrane[1] / 2))

    monkeypatch.setattr(pipeline, "check_solid", demanding)
    out = tmp_path / "out"
    assert_one_line_error(*cli("design", phantom1_dir, "--mask", "nasal", "--stock", "none", "--out", out), "printability", "membrane_min_mm")
    assert not out.exists() or not any(out.iterdir())


def test_a_frame_failing_its_check_is_the_one_line_even_when_pressing_fails_too(cli, tmp_path, phantom1_dir, placed1, monkeypatch):
    """The frame, made in a thread while the cushion is pressed, failing its closed-solid check
    while the pressing beside it fails too: the frame check's line (the mould and the frame are
    checked before the pressing's result is used), exit 2, nothing written."""
    import cpapfit.pipeline as pipeline
    from cpapfit.errors import InputError

    def leaking(mesh, name):
        raise SolidError(f"{name} is not a closed solid")

    def unpressed(*args, **kwargs):
        raise InputError("no rim over the face")

    monkeypatch.setattr(pipeline, "check_closed", leaking)
    monkeypatch.setattr(pipeline, "pressed_asleep", unpressed)
    out = tmp_path / "out"
    assert_one_line_error(*cli("design", phantom1_dir, "--mask", "nasal", "--stock", "none", "--out", out), "the frame is not a closed solid")
    assert not out.exists() or not any(out.iterdir())


def test_a_bug_gives_one_line_and_writes_nothing(cli, tmp_path, phantom1_dir, monkeypatch):
    """An unexpected exception inside a stage (a bug, not the input): exit 1, one line saying so and
    what to do, no traceback, no output."""
    import cpapfit.pipeline as pipeline

    def broken(*args, **kwargs):
        raise RuntimeError("a stage broke")

    monkeypatch.setattr(pipeline, "register_template", broken)
    out = tmp_path / "out"
    code, _, err = cli("design", phantom1_dir, "--mask", "nasal", "--out", out, "--quiet")
    assert code == 3 and "Traceback" not in err
    assert err.strip().splitlines() == [err.strip()] and err.startswith("cpapfit: internal error: RuntimeError: a stage broke")
    assert not out.exists() or not any(out.iterdir())


def test_a_refused_scan_removes_the_earlier_design_in_its_folder_and_says_so(cli, tmp_path):
    """A folder holding an earlier design (its manifest) and a scan that is refused: the folder
    must not go on holding a cushion that reads as this scan's."""
    out = tmp_path / "patient"
    out.mkdir()
    (out / "manifest.json").write_text(json.dumps({"files": ["cushion.stl"]}))
    (out / "cushion.stl").write_text("the earlier scan's cushion")
    (tmp_path / "empty.ply").write_bytes(b"")
    assert_one_line_error(*cli("design", tmp_path / "empty.ply", "--out", out), "empty", f"earlier design in {out} was removed")
    assert not out.exists()


def test_a_design_into_a_folder_of_other_files_is_refused_and_leaves_them(cli, tmp_path, phantom1_dir):
    (tmp_path / "notes.txt").write_text("the clinic's own file")
    assert_one_line_error(*cli("design", phantom1_dir, "--out", tmp_path), "not a cpapfit design folder", "another --out")
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"] and (tmp_path / "notes.txt").read_text() == "the clinic's own file"


def test_console_entry_point_prints_no_traceback(tmp_path):
    res = subprocess.run(
        [sys.executable, "-m", "cpapfit", "inspect", str(tmp_path / "missing.obj")], capture_output=True, text=True
    )
    assert_one_line_error(res.returncode, res.stdout, res.stderr, "no such file")


def test_obj_cut_mid_line(cli, tmp_path, phantom1):
    text = trimesh.Trimesh(phantom1.surface, phantom1.faces).export(file_type="obj")
    cut = text.index("\nf ", int(len(text) * 0.8)) + 5  # inside a face line: "f 12"
    (tmp_path / "cut.obj").write_text(text[:cut])
    assert_one_line_error(*cli("inspect", tmp_path / "cut.obj"), "truncated")


def test_evaluate_refuses_bad_cushions_and_options_before_any_work(cli, tmp_path, phantom1_dir):
    out = tmp_path / "fit.json"
    ring = trimesh.creation.annulus(0.02, 0.025, 0.01)  # a cushion exported in metres
    ring.export(tmp_path / "metres.stl")
    cases = [
        (("--cushion", tmp_path / "none.stl"), "no such file"),
        (("--cushion", tmp_path / "metres.stl"), "millimetres"),
        (("--cushion", tmp_path / "metres.stl", "--generic"), "--mask"),
        (("--cushion", tmp_path / "metres.stl", "--stock", "M"), "--mask"),
        (("--cushion", tmp_path / "metres.stl", "--mask", "oronasal", "--stock", "W"), "--stock"),
        (("--cushion", tmp_path / "metres.stl", "--force", "-3"), "--force"),
        (("--cushion", tmp_path / "metres.stl", "--cpap", "80"), "--cpap"),
    ]
    for args, word in cases:
        assert_one_line_error(*cli("evaluate", phantom1_dir, *args, "--out", out), word)
        assert not out.exists()


def test_design_and_batch_refuse_a_stock_size_the_mask_does_not_have(cli, tmp_path, phantom1_dir):
    for command in ("design", "batch"):
        out = tmp_path / command
        assert_one_line_error(*cli(command, phantom1_dir, "--mask", "oronasal", "--stock", "W", "--out", out), "--stock W", "S, M, L")
        assert not out.exists()


def test_an_output_folder_that_is_a_file_is_one_line(cli, tmp_path):
    (tmp_path / "taken").write_text("not a folder")
    assert_one_line_error(*cli("phantom", "--seed", "1", "--out", tmp_path / "taken" / "sub"), "taken")


def test_the_summary_of_a_rim_with_no_scan_under_it_says_so():
    from cpapfit.commands import design_summary
    fit = {"mask": "nasal", "cushion": {"width_mm": 52.0, "height_mm": 50.0, "depth_mm": 40.0, "min_wall_mm": 2.01, "membrane_min_mm": 0.5},
           "fit_before_compression": {"rim_gap_median_mm": None, "rim_gap_max_mm": None, "rim_covered_fraction": 0.0}}
    assert design_summary(fit).endswith("rim-to-skin gap before pre-load no scan data under the rim")


def test_a_face_no_stock_size_seats_on_is_designed_and_says_so(cli, tmp_path, phantom1_dir, placed1, monkeypatch):
    """Every stock size asked for finds no seat on the face: the custom cushion is still designed,
    fit.json (valid) and the report saying why no stock cushion is compared, the summary line too."""
    import cpapfit.stock_fit as stock_fit

    monkeypatch.setattr(stock_fit, "seat_step", lambda *args, **kwargs: None)
    out = tmp_path / "out"
    code, _, err = cli("design", phantom1_dir, "--mask", "nasal", "--stock", "gauge", "--out", out)
    assert code == 0, err
    fit = written(out / "fit.json")
    assert "stock" not in fit and "stock_fitting" not in fit and fit["custom"]["leak_l_min"] <= 2.0
    assert fit["stock_not_fitted"].startswith("no nasal stock size tried") and "no stock cushion compared: no nasal stock size" in err
    assert "No stock cushion compared: no nasal stock size tried" in (out / "report.html").read_text()


def test_a_twisted_seal_is_refused_with_what_to_do(cli, tmp_path, phantom1_dir, placed1, monkeypatch):
    """A seal curve that crosses itself (two opposite stretches swapped, as a misplaced template
    can carry) puts the cushion's rim off the skin: refused by the rim gate before any solid is
    built, saying what to do, nothing written. A cushion that still crosses itself is refused too, by
    its cause: its wall's surface twisted (what to do), its membrane's, or, both clean, its solid folded."""
    import dataclasses

    import cpapfit.pipeline as pipeline

    real = pipeline.transfer_contact

    def twisted(*args):
        contact = real(*args)
        n = len(contact.curve)
        order = np.r_[n // 2: n // 2 + n // 8, n // 8: n // 2, 0: n // 8, n // 2 + n // 8: n]
        return dataclasses.replace(contact, curve=contact.curve[order], normals=contact.normals[order], on_scan=contact.on_scan[order])

    monkeypatch.setattr(pipeline, "transfer_contact", twisted)
    out = tmp_path / "out"
    assert_one_line_error(*cli("design", phantom1_dir, "--mask", "nasal", "--out", out), "rim_gap_mm", "off the scanned skin", "--landmarks")
    assert not out.exists() or not any(out.iterdir())
    a = trimesh.creation.box((10, 10, 10))
    crossing = trimesh.util.concatenate([a, a.copy().apply_translation((3, 4, 2.5))])  # two boxes through each other
    clean = template_cushion("nasal")
    n = len(clean.control)
    swapped = dataclasses.replace(clean, control=clean.control[np.r_[n // 2: n // 2 + n // 8, n // 8: n // 2, 0: n // 8, n // 2 + n // 8: n]])
    with pytest.raises(SolidError, match="would cross itself .* twisted, .* give landmarks with --landmarks, or rescan facing the camera; nothing was written$"):
        pipeline._checked(swapped, crossing, (5.0, 2.0), (5.0, 0.5), "the nasal cushion", "render")
    with pytest.raises(SolidError, match="would cross itself .* its surface does not, but its 2 mm wall or 0.5 mm membrane folds"):
        pipeline._checked(clean, crossing, (5.0, 2.0), (5.0, 0.5), "the nasal cushion", "render")
    flaps = dataclasses.replace(clean, membrane=swapped.control[:, :MEMBRANE_ROWS])  # the wall clean, its membrane twisted
    with pytest.raises(SolidError, match="would cross itself .* its membrane's flaps run into each other"):
        pipeline._checked(flaps, crossing, (5.0, 2.0), (5.0, 0.5), "the nasal cushion", "render")
