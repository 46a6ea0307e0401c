"""The report: pictures and their layout, warnings, report.html in headless Chromium offline.

One design of the synthetic subject of seed 1, with its evaluation, is shared by all tests."""

import io
import json
import math

import numpy as np
import pytest
from matplotlib import colormaps
from PIL import Image

from cpapfit.align.morphable import MorphableParams
from cpapfit.align.nonrigid import morphable_share
from cpapfit.outputs import input_sha256, run_date
from cpapfit.report.advice import Notice, at_seal_force, fit_notices, gate_notices, landmark_notices, scan_notices
from cpapfit.report.assemble import Provenance, evaluated_rims, pressure_scale, report_files
from cpapfit.report.frame import Face, seal_view, shoot, to_pixels
from cpapfit.report.figure import PANEL, ColourScale, panels_png
from cpapfit.report.pictures import OPEN, OPEN_RGB, rim_image
from cpapfit.loops import longest_run, loop_lengths
from cpapfit.template import load_template

from browser import CHROMIUM, Chromium

PROVENANCE = Provenance("phantom1", "0" * 64, "2024-01-01 00:00 UTC")


@pytest.fixture(scope="session")
def designed1(nasal1):
    """(scan, Design) of seed 1's nasal design."""
    return nasal1.scan, nasal1.design


@pytest.fixture(scope="session")
def report(nasal1, tmp_path_factory):
    """(folder, {name: bytes} of the pictures and report.html, fit record, mask record) of seed 1's
    nasal design (`nasal1`, its report drawn by `cpapfit.design`), written to a folder."""
    files = {name: data for name, data in nasal1.files.items() if name.endswith(".png") or name == "report.html"}
    fit, mask = json.loads(nasal1.files["fit.json"]), json.loads(nasal1.files["mask.json"])
    folder = tmp_path_factory.mktemp("report")
    for name, data in files.items():
        (folder / name).write_bytes(data)
    (folder / "fit.json").write_text(json.dumps(fit))
    return folder, files, fit, mask


EXPECTED_SIZES = {  # (width, height) px: panels of 640 x 480 at their own pixels, with titles, colour bars, legends
    "scan_landmarks.png": (820, 570), "registration_residual.png": (820, 570), "contact_curve.png": (1315, 595),
    "cushion_on_face.png": (1315, 570), "mask_on_face.png": (1315, 570), "rim_gap.png": (1475, 595), "rim_gap_profile.png": (900, 420),
    "rim_pressure.png": (1475, 595), "rim_pressure_profile.png": (900, 420), "leak.png": (1315, 595),
    "states_pressure.png": (2785, 1110),
}


def test_every_picture_is_there_of_its_size_and_not_blank(report):
    _, files, _, _ = report
    assert set(EXPECTED_SIZES) | {"report.html"} == set(files)
    for name, size in EXPECTED_SIZES.items():
        image = np.asarray(Image.open(io.BytesIO(files[name])).convert("RGB"))
        assert image.shape[1::-1] == size, name
        not_white = (image < 235).any(axis=2).mean()
        colours = len(np.unique(image.reshape(-1, 3)[::7], axis=0))
        least = 0.03 if name.endswith("profile.png") else 0.1  # a line plot is mostly paper, a rendering has the face
        assert not_white > least and colours > 200, (name, not_white, colours)


def test_rim_colours_follow_the_pressure_and_open_stretches_are_dark(designed1):
    scan, d = designed1
    rims = evaluated_rims(d)
    rim = rims["stock"]
    sim = d.alignment.similarity
    shot = shoot(Face(scan.vertices, scan.faces), seal_view(sim, rim.points))
    scale = pressure_scale(rims, d.fit_params.window_kpa)
    image = rim_image(shot, rim.points, rim.pressure_kpa, scale, rim.open).astype(int)
    px, seen = to_pixels(shot, rim.points)
    assert seen.mean() > 0.6
    seen &= np.isfinite(rim.pressure_kpa)  # over scanned skin
    at = image[np.round(px[seen, 1]).astype(int), np.round(px[seen, 0]).astype(int)]
    want = np.where(rim.open[seen, None], OPEN_RGB, scale.rgb(rim.pressure_kpa[seen])).astype(int)
    close = np.abs(at - want).max(axis=1) <= 40  # neighbouring points (about 2 px apart) overdraw a little
    assert close.mean() > 0.9, close.mean()
    assert (np.abs(image - shot.image).sum(axis=2) > 0).mean() < 0.1  # the rest of the picture is untouched


def test_points_behind_the_face_are_not_drawn(designed1):
    scan, d = designed1
    curve, axis = d.contact.curve, d.cushion.axis
    shot = shoot(Face(scan.vertices, scan.faces), seal_view(d.alignment.similarity, curve))
    _, in_front = to_pixels(shot, curve + 3.0 * axis)
    px, behind = to_pixels(shot, curve - 15.0 * axis)
    on_face = np.isfinite(shot.depth[np.round(px[:, 1]).astype(int), np.round(px[:, 0]).astype(int)])  # not seen through a hole
    assert in_front.mean() > 0.9 and on_face.mean() > 0.5 and not behind[on_face].any()


def test_longest_run_wraps_around_the_loop():
    t = np.linspace(0, 2 * np.pi, 100, endpoint=False)
    loop = 50.0 * np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)  # circumference 314 mm, 3.14 mm per point
    flag = np.zeros(100, dtype=bool)
    flag[[95, 96, 97, 98, 99, 0, 1, 2, 3]] = True
    flag[40:43] = True
    length, middle = longest_run(flag, loop_lengths(loop))
    assert length == pytest.approx(9 * 2 * np.pi * 50 / 100, rel=1e-3) and middle in (98, 99, 0)
    assert longest_run(np.zeros(100, dtype=bool), loop_lengths(loop)) == (0.0, -1)


def test_holes_under_the_seal_and_low_confidence_are_warned(designed1):
    _, d = designed1
    sim, curve = d.alignment.similarity, d.contact.curve
    assert scan_notices(curve, np.ones(len(curve), dtype=bool), sim, "nasal") == []
    hole = np.ones(len(curve), dtype=bool)
    hole[:10] = False  # about 12 mm at the start of the loop: the nasal bridge
    (notice,) = scan_notices(curve, hole, sim, "nasal")
    assert notice.level == "check" and "nasal bridge" in notice.text and "Rescan" not in notice.text
    lm = d.alignment.landmarks
    assert landmark_notices(lm) == []
    doubtful = type(lm)(lm.points, lm.template_index, np.where(np.arange(len(lm.points)) % 3 == 0, 0.1, 1.0), lm.path)
    assert "disagree" in landmark_notices(doubtful)[0].text


def test_a_rim_pressing_too_hard_is_advised_by_whether_a_lower_force_can_ease_it(designed1):
    """A custom rim pressing 5 kPa (over the 4.3 kPa window top) along 10 of its points: the
    notice says where and, strapped above the least force that seals it, to lower the force; at
    that force (within 1 %), that its shape presses there instead."""
    from cpapfit.report.rim import RimFit

    _, d = designed1
    curve = d.contact.curve
    pressure = np.where(np.arange(len(curve)) < 10, 5.0, 2.0)
    rims = {"custom": RimFit(curve, np.zeros(len(curve)), pressure, np.zeros(len(curve), dtype=bool))}
    for force, at_least in ((3.0, False), (2.02, True)):
        fit = {"custom": {"headgear_force_n": force, "seal_force_n": 2.0}}
        assert at_seal_force(fit) is at_least
        (notice,) = fit_notices(rims, (1.2, 4.3), d.alignment.similarity, "nasal", at_seal_force(fit))
        assert "presses above 4.3 kPa" in notice.text and "nasal bridge" in notice.text
        assert ("least that seals" in notice.text) is at_least and ("lower the headgear force" in notice.text) is not at_least
    assert at_seal_force({"custom": {"headgear_force_n": 2.0, "seal_force_n": None}}) is False


def test_the_report_advises_a_rescan_exactly_when_fit_json_does(designed1, report):
    """The report's "Rescan advised" and its reasons are the quality gates' (fit.json), not its own."""
    scan, d = designed1
    _, files, fit, mask = report
    assert fit["rescan_advised"] is False and "Rescan advised" not in files["report.html"].decode()
    message = "the scan covers 50 % of the nasal mask's seal region; rescan facing the camera (rescan advised below 75 %)"
    flagged = {**fit, "rescan_advised": True, "warnings": [{"code": "coverage", "message": message}]}
    page = report_files(d, scan, flagged, mask, PROVENANCE)["report.html"].decode()
    assert "Rescan advised." in page and "The scan covers 50 % of the nasal mask" in page
    assert gate_notices(flagged) == [Notice("rescan", message[0].upper() + message[1:] + ".")]


def shown_numbers_match(shown: list, record: dict) -> None:
    """Every [data-key, data-scale, text] shown equals the record's value at that key, to the digits shown."""
    for key, scale, text in shown:
        value = record
        for part in key.split("."):
            value = value[int(part)] if isinstance(value, list) else value[part]
        decimals = len(text.split(".")[1]) if "." in text else 0
        assert math.isclose(float(text), value * float(scale), abs_tol=0.5 * 10 ** -decimals + 1e-9), (key, text, value)


def test_report_html_in_headless_chromium_offline(report, tmp_path):
    assert CHROMIUM.exists(), "Debian's chromium is needed: `make test` installs it (apt-get install chromium)"
    folder, _, fit, mask = report
    browser = Chromium(tmp_path / "profile")
    try:
        browser.open(folder / "report.html")
        browser.settle(1.5)
        shown = browser.evaluate("[...document.querySelectorAll('[data-key]')].map(e => [e.dataset.key, e.dataset.scale, e.textContent])")
        shown_mask = browser.evaluate("[...document.querySelectorAll('[data-mask-key]')]"
                                      ".map(e => [e.dataset.maskKey, e.dataset.scale, e.textContent])")
        box = browser.evaluate("(() => { const r = document.querySelector('#viewer .gl-container canvas').getBoundingClientRect();"
                               " return {x: r.x + scrollX, y: r.y + scrollY, width: r.width, height: r.height}; })()")
        shot = np.asarray(Image.open(io.BytesIO(browser.screenshot(clip=box))).convert("RGB")).astype(int)
        errors = browser.console_errors()
        resources = browser.evaluate("performance.getEntriesByType('resource').map(e => e.name)")
    finally:
        browser.close()
    assert errors == []
    assert resources == []  # nothing fetched: everything is inline
    keys = {k for k, _, _ in shown}
    assert {"headgear_force_n", "custom.pressure_max_kpa", "stock.leak_l_min", "stock.headgear_force_n", "custom.window_fraction",
            "cushion.min_wall_mm", "states.2.custom.leak_l_min", "states.7.stock.pressure_max_kpa"} <= keys
    shown_numbers_match(shown, fit)
    assert {"dead_space_ml", "vents.flow_l_min.4_cmh2o", "vents.flow_l_min.10_cmh2o", "vents.flow_l_min.20_cmh2o"} <= {k for k, _, _ in shown_mask}
    shown_numbers_match(shown_mask, mask)
    skin = (np.abs(shot - [217, 192, 173]).max(axis=2) < 60).mean()  # the face, shaded
    green = ((shot[..., 1] > shot[..., 0] + 30) & (shot[..., 1] > shot[..., 2])).mean()  # the custom cushion, in the window
    assert skin > 0.1 and green > 0.005, (skin, green)


def test_input_hash_and_date(phantom1_dir, tmp_path, monkeypatch):
    folder = tmp_path / "capture"
    folder.mkdir()
    for f in phantom1_dir.rglob("*"):
        if f.is_file():
            (folder / f.relative_to(phantom1_dir)).parent.mkdir(parents=True, exist_ok=True)
            (folder / f.relative_to(phantom1_dir)).write_bytes(f.read_bytes())
    assert input_sha256(folder) == input_sha256(phantom1_dir)
    (folder / "intrinsics.json").write_text((folder / "intrinsics.json").read_text() + " ")
    assert input_sha256(folder) != input_sha256(phantom1_dir)
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1700000000")
    assert run_date() == "2023-11-14 22:13 UTC"


def test_the_viewer_decimates_a_dense_face_it_was_handed_read_only():
    """A stage's frozen (read-only) arrays, 20 480 triangles: the 3-D view keeps at most 1 000, all
    within 1 mm of the sphere they came from (a dense scan once crashed the report here)."""
    import trimesh

    from cpapfit.report.frame import Face
    from cpapfit.report.viewer import viewer_face

    sphere = trimesh.creation.icosphere(5, radius=50.0)
    face = Face(np.array(sphere.vertices), np.array(sphere.faces, dtype=np.int64))
    shown = viewer_face(face, np.zeros(3), 200.0, 1000)
    assert 0 < len(shown.faces) <= 1000
    assert np.abs(np.linalg.norm(shown.vertices, axis=1) - 50.0).max() <= 1.0


def test_a_dense_crop_reaches_the_decimator_thinned(monkeypatch):
    """A crop of 327 680 triangles, for 1 000 shown: the quadric decimator (which keeps arrays the
    size of its largest input for the rest of the process) is handed the crop vertex-clustered to
    CLUSTERED to 2.5 times the triangles shown; a crop of at most CLUSTERED times goes to it whole."""
    import trimesh

    from cpapfit.report import viewer
    from cpapfit.report.frame import Face

    handed = []
    decimate = trimesh.Trimesh.simplify_quadric_decimation
    monkeypatch.setattr(trimesh.Trimesh, "simplify_quadric_decimation",
                        lambda mesh, **kw: handed.append(len(mesh.faces)) or decimate(mesh, **kw))
    for level, most in ((7, 1000), (3, 400)):
        sphere = trimesh.creation.icosphere(level, radius=50.0)
        viewer.viewer_face(Face(np.array(sphere.vertices), np.array(sphere.faces, dtype=np.int64)), np.zeros(3), 200.0, most)
    assert viewer.CLUSTERED * 1000 <= handed[0] <= 2.5 * viewer.CLUSTERED * 1000
    assert handed[1] == 1280


def test_the_other_starts_contact_band_is_recorded_and_told(designed1, report):
    """Seed 1 (template-made) weighs its affine start's run most; fit.json gives the product, the
    morphable run's share (`morphable_share` of the product, under a half) and how far the
    morphable start's run alone put the nasal contact band (measured here), and the contact-curve
    caption names that start and says the same to 0.1 mm."""
    _, d = designed1
    _, files, fit, _ = report
    reg, band = d.registration, load_template().regions["nasal"].band
    apart = np.linalg.norm(reg.vertices[band] - reg.other_run[band], axis=1).mean()
    record = fit["registration"]
    share = morphable_share(record["start_product"], MorphableParams().blend)
    assert record["start"] == "affine" and record["morphable_share"] == pytest.approx(share, abs=1e-4) and share < 0.5
    assert 0.05 < apart < 3.0 and record["other_start_band_mm"] == pytest.approx(apart, abs=1e-3)
    assert f"fitted from the morphable start alone put the contact band {apart:.1f} mm (mean) from this one" in files["report.html"].decode()


def test_pictures_are_laid_out_at_their_own_pixels_beside_their_colour_bar():
    """Each picture of a panel lands in the PNG pixel for pixel (no resampling), in rows of `columns`;
    the colour bar spans the pictures' rows from the first's top to the last's bottom; the legend lies
    below the last row."""
    h, w = 48, 64
    pictures = [np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8) for seed in range(4)]
    scale = ColourScale(colormaps["viridis"], 0.0, 1.0, "a value (mm)", ((0.5, "half"),))
    out = np.asarray(Image.open(io.BytesIO(panels_png(pictures, list("abcd"), "four", scale, ((OPEN, "open"),), columns=2))).convert("RGB"))
    width, top = PANEL.pad + 2 * w + PANEL.gap + sum(PANEL.bar), PANEL.heading + PANEL.title
    assert out.shape == (PANEL.heading + 2 * (PANEL.title + h) + PANEL.legend, width, 3)
    for i, picture in enumerate(pictures):
        row, left = top + (i // 2) * (PANEL.title + h), PANEL.pad + (i % 2) * (w + PANEL.gap)
        assert np.array_equal(out[row:row + h, left:left + w], picture), i
    bottom = top + 2 * h + PANEL.title
    bar = (out[:, width - PANEL.bar[2] - PANEL.bar[1] // 2] < 235).any(axis=1)  # its middle column: coloured or outlined
    assert bar[top:bottom].all() and not bar[:top - 1].any() and not bar[bottom + 1:].any()
    assert len(np.unique(out[top + 2:bottom - 2, width - PANEL.bar[2] - PANEL.bar[1] // 2], axis=0)) > 20  # a gradient
    assert (out[bottom:] < 235).any(axis=2).sum() > 50  # the legend's mark and words, under the pictures
