"""The public API: the README's five-line Python design, its files against the shipped schemas."""

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from cpapfit.errors import InputError

from records import written


def test_the_python_quick_start_designs_and_saves_files_that_follow_the_schemas(nasal1, phantom1_dir, tmp_path):
    import cpapfit

    subject = cpapfit.phantom(1, tmp_path / "subject", population="template")
    assert {p.relative_to(subject): p.read_bytes() for p in subject.rglob("*") if p.is_file()} == {
        p.relative_to(phantom1_dir): p.read_bytes() for p in phantom1_dir.rglob("*") if p.is_file()}
    result = nasal1  # cpapfit.design(cpapfit.load_scan(subject), mask="nasal", params=cpapfit.Params(stock="gauge"))
    folder = result.save(tmp_path / "out")
    fit = written(folder / "fit.json")
    assert fit == result.fit and fit["schema_version"] == 3 and result.quality["rescan_advised"] == fit["rescan_advised"]
    assert fit["custom"]["leak_l_min"] <= 1.0 and fit["stock_fitting"]["size"] == fit["stock_fitting"]["gauge_size"]
    curve = written(folder / "contact_curve.json")
    assert np.allclose(curve["points"], result.design.contact.curve, atol=1e-4)  # mm, as designed
    assert trimesh.load(folder / "cushion.stl").is_watertight and not list(folder.parent.glob(".*"))  # no staging left
    mask = written(folder / "mask.json")  # the nasal frame: no valve, dead space within 120 ml
    assert mask["valve"] is None and 20.0 < mask["dead_space_ml"] <= 120.0 and mask["assembly"]["interference_mm3"] < 0.01
    manifest = written(folder / "manifest.json")
    assert sorted(manifest["files"]) == sorted(result.files) == sorted(p.name for p in folder.iterdir() if p.name != "manifest.json")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("not a design")
    with pytest.raises(InputError, match="not a cpapfit design folder"):
        result.save(tmp_path / "mine")  # a folder of the user's own is never replaced
    assert (tmp_path / "mine" / "notes.txt").read_text() == "not a design"


def test_the_command_line_starts_without_loading_the_stages():
    """`import cpapfit.cli` (what `cpapfit --help` runs) loads neither trimesh nor the report."""
    code = "import sys, cpapfit.cli; print(sorted(m for m in ('trimesh', 'matplotlib', 'plotly', 'cpapfit.pipeline') if m in sys.modules))"
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "[]"


def test_io_imports_none_of_the_design_stages():
    """`cpapfit.io` reads and writes files at the edge: loading all of it loads none of the stages
    from registration on (nor the pipeline, the records or the jobs around them)."""
    stages = ("pipeline", "align.nonrigid", "cushion", "quality", "fabrication", "evaluation", "stock_fit", "report",
              "records", "outputs", "jobs")
    code = ("import sys, pkgutil, importlib, cpapfit.io as io\n"
            "[importlib.import_module(f'cpapfit.io.{m.name}') for m in pkgutil.iter_modules(io.__path__)]\n"
            f"print(sorted(m for m in sys.modules if any(m == 'cpapfit.' + s or m.startswith('cpapfit.' + s + '.') for s in {stages!r})))")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "[]"


def test_the_registration_parameters_in_params_reach_the_registration(phantom1_dir, monkeypatch):
    import cpapfit
    from cpapfit import pipeline

    class Registering(Exception):
        pass

    def register(*args):
        raise Registering(args[4])  # register(template, faces, scan, landmarks, params, ...)

    monkeypatch.setattr(pipeline, "register", register)
    mine = cpapfit.NonrigidParams(user_trust_mm=1.0)
    with pytest.raises(Registering) as raised:
        cpapfit.design(cpapfit.load_scan(phantom1_dir), params=cpapfit.Params(registration=mine), report=False)
    assert raised.value.args[0] is mine


def test_evaluate_places_the_template_with_the_landmarks_and_settings_it_is_given(phantom1_dir, tmp_path, monkeypatch):
    """`evaluate` places the template itself (the design's placement is not reused): with the user's
    landmarks read in the scan's units and the registration, quality and landmark-noise settings of
    its `Params`."""
    import cpapfit
    from cpapfit import api

    class Placing(Exception):
        pass

    def place_template(scan, landmarks, **settings):
        raise Placing(scan, landmarks, settings)

    monkeypatch.setattr(api, "place_template", place_template)
    scan = cpapfit.load_scan(phantom1_dir)
    index = [1, 4, 33, 263]
    (tmp_path / "lm.json").write_text(json.dumps({"points": scan.vertices[:4].tolist(), "template_index": index}))
    params = cpapfit.Params(registration=cpapfit.NonrigidParams(user_trust_mm=1.0), quality=cpapfit.QualityParams(residual_flag_mm=0.9),
                            landmark_noise=cpapfit.LandmarkNoise(sigma_mm=1.5, seed=3))
    with pytest.raises(Placing) as raised:
        cpapfit.evaluate(scan, trimesh.creation.icosphere(), landmarks=tmp_path / "lm.json", params=params)
    placed_on, landmarks, settings = raised.value.args
    assert placed_on is scan and landmarks.path == "user" and landmarks.template_index.tolist() == index
    assert np.array_equal(landmarks.points, scan.vertices[:4])
    assert settings == {"params": params.registration, "quality": params.quality, "landmark_noise": params.landmark_noise}


def test_the_landmark_noise_in_params_reaches_the_detected_landmarks(nasal1, phantom1_dir, monkeypatch):
    """Params(landmark_noise=...) moves the landmarks the registration starts from: seed 1's
    detection (nasal1's) with that noise, along the skin (`on_skin`), bit for bit."""
    import cpapfit
    from cpapfit import pipeline
    from cpapfit.landmarks.noise import on_skin

    class Registering(Exception):
        pass

    def register(*args):
        raise Registering(args[3])  # register(template, faces, scan, landmarks, ...)

    monkeypatch.setattr(pipeline, "register", register)
    scan = cpapfit.load_scan(phantom1_dir)
    with pytest.raises(Registering) as raised:
        cpapfit.design(scan, params=cpapfit.Params(landmark_noise=cpapfit.LandmarkNoise(sigma_mm=2.0, seed=5)), report=False)
    found, noisy = nasal1.design.alignment.landmarks, raised.value.args[0]
    assert found.path == noisy.path == "image" and np.array_equal(noisy.template_index, found.template_index)
    assert np.array_equal(noisy.points, on_skin(scan, found.points, 2.0, 5))
    assert 1.0 < np.linalg.norm(noisy.points - found.points, axis=1).mean() < 4.0
