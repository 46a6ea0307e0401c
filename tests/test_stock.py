"""Stock cushions: sizes spanning the population, a real membrane, the gauge, and a clinic's seating."""

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from cpapfit.cushion.generic import AXIS, NOSE_TIP, UP, contact_on
from cpapfit.cushion.nurbs import CushionParams, design_cushion
from cpapfit.cushion.contact import SAMPLES
from cpapfit.cushion.population import POPULATION, drawn, population, population_gauge
from cpapfit.cushion.stock import BRIDGE, SIZES, SLACK_MM, mean_face, set_back, size_scale, stock_cushion, stock_solid
from cpapfit.evaluation.fit import KPA_PER_CMH2O, Face
from cpapfit.evaluation import rim
from cpapfit.evaluation.membrane import MEMBRANE_MAX_MM, face_thickness_mm, reach_mm
from cpapfit.evaluation.states import CPAP_RANGE_CMH2O
from cpapfit.errors import InputError
from cpapfit.report.page import cushion_label, settings_line
from cpapfit import stock_fit
from cpapfit.stock_fit import COMFORT_N, GRID, MARGIN, SEAT_STEPS_MM, _placed, _refined_stock, compared_stock, gauge_size, seated
from cpapfit.template import load_template


def face_scaled(scale: np.ndarray) -> Face:
    """The ICT mean face scaled about its nasal bridge (template frame), its own registered template."""
    v = (mean_face() - mean_face()[BRIDGE]) * scale + mean_face()[BRIDGE]
    mesh = trimesh.Trimesh(v, load_template().faces, process=False)
    return Face(mesh, mesh, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))


def test_the_shipped_population_is_a_fresh_draw():
    """The shipped figures (`tools/build_stock_family.py`) are those the ICT model and the
    template give now: every gauge measure and seal depth within 1e-9 mm."""
    fresh = drawn()
    for mask, (gauge, depth) in population().items():
        assert gauge.shape == (POPULATION,) and depth.shape == (POPULATION, SAMPLES)
        np.testing.assert_allclose(gauge, fresh[mask][0], rtol=0, atol=1e-9)
        np.testing.assert_allclose(depth, fresh[mask][1], rtol=0, atol=1e-9)


def test_the_shipped_solids_are_those_made_afresh():
    """Every size's shipped solid (`tools/build_stock_family.py`) is the one `stock_cushion` makes
    now from the shipped population: the same triangles, every vertex within one float32 step (the
    union's manifold3d works in float32: a last bit of its input that differs, as another CPU's
    BLAS may make it, moves a vertex by a step, 7.6e-6 mm at 64-128 mm)."""
    for mask, sizes in SIZES.items():
        for size in sizes:
            shipped, fresh = stock_solid(mask, size), stock_cushion(mask, size)[1]
            assert np.array_equal(shipped.faces, fresh.faces), (mask, size)
            np.testing.assert_array_max_ulp(shipped.vertices.astype(np.float32), fresh.vertices.astype(np.float32), maxulp=1)


@pytest.mark.parametrize("mask", ["nasal", "oronasal"])
def test_the_sizes_span_the_populations_gauge_measure(mask):
    """S and L are the 15th and 85th percentiles of the gauge's measure over the population, M its median:
    the rims of the cushions made scale by them (their width across the face within 1.5 %)."""
    measures = population_gauge(mask)
    width = {s: np.ptp(stock_cushion(mask, s)[0].grid()[:, 0, 0]) for s in ("S", "M", "L")}
    for size, pct in (("S", 15), ("L", 85)):
        expected = np.percentile(measures, pct) / np.median(measures)
        assert size_scale(mask, size)[0] == pytest.approx(expected, rel=1e-12)
        assert width[size] / width["M"] == pytest.approx(expected, rel=0.015)
    assert 0.8 < size_scale(mask, "S")[0] < 0.97 and 1.03 < size_scale(mask, "L")[0] < 1.2


@pytest.mark.parametrize("mask", ["nasal", "oronasal"])
def test_a_stock_rim_stands_back_where_the_population_stands_out(mask):
    """The set back is most at the nasal bridge, where faces differ most in depth (1-4 mm); the M cushion's seal row stands that far back along the axis
    from the same design on the mean face without it (within 0.25 mm at every point)."""
    back = set_back(mask)
    contact = contact_on(mask, face_scaled(np.ones(3)).scan)
    bridge = np.argmin(np.linalg.norm(contact.curve - mean_face()[BRIDGE], axis=1))
    assert 1.0 < back.max() < 4.0 and back[bridge] > back.max() - 0.3
    plain = design_cushion(contact, AXIS, UP, mean_face()[NOSE_TIP]).grid()[:, 0]
    stood_back = (stock_cushion(mask, "M")[0].grid()[:, 0] - plain) @ AXIS
    assert np.abs(stood_back - back[cKDTree(contact.curve).query(plain)[1]]).max() < 0.25


def test_a_stock_cushion_is_a_closed_wall_with_a_thin_membrane():
    _, solid = stock_cushion("oronasal", "M")
    assert solid.is_watertight and solid.is_volume
    thickness = face_thickness_mm(solid)
    area = solid.area_faces
    thin = thickness < MEMBRANE_MAX_MM
    assert 0.05 < area[thin].sum() / area.sum() < 0.5  # a membrane, not all membrane
    assert np.median(thickness[thin]) == pytest.approx(0.5, abs=0.1)


@pytest.mark.parametrize("size", ["S", "L"])
def test_the_gauge_picks_the_size_made_for_a_face_that_size(size):
    assert gauge_size("oronasal", np.asarray(face_scaled(size_scale("oronasal", size)).registered.vertices)) == size


def test_the_size_made_on_a_face_seats_on_its_bridge_and_seals_within_comfort():
    """The M oronasal cushion on the face it was made on: seated within a millimetre of the nasal
    bridge, sealed (no leak) at under COMFORT_N with its peak under the capillary pressure; its
    membrane, sized to reach SLACK_MM at the lowest CPAP pressure, reaches 1.5 mm or more there
    as measured on half its rim (the section from the rim point, not the flap's root)."""
    fit = seated("oronasal", "M", face_scaled(np.ones(3)))
    summary = fit.fit.summary()
    assert fit.sealed and fit.fit.force_n <= COMFORT_N
    assert np.abs(fit.offset_mm).max() <= 1.0
    assert summary["leak_l_min"] == 0.0 and summary["pressure_max_kpa"] < 4.3
    assert summary["rim_covered_fraction"] == 1.0
    rim = fit.fit.rim
    assert np.median(reach_mm(rim.membrane_mm, rim.membrane_thickness_mm, CPAP_RANGE_CMH2O[0] * KPA_PER_CMH2O)) >= SLACK_MM - 0.5


def test_the_seats_tried_are_the_bridge_grid_then_the_finer_grid_about_its_best(monkeypatch):
    """`seated`'s steps (`seat_step`, each of which a worker or this process may take): the 3 x 3
    seats SEAT_STEPS_MM[0] apart about the nasal bridge, then the 8 new ones SEAT_STEPS_MM[1] apart
    about the best of those, each pressed once; the best seat by rank, seats with no rim left out.
    Pressing is stood in for by a rank that falls towards (1.2, -2.9) mm, no rim left of -1.5 mm."""
    pressed = []

    def press(size, zone, face, offset, params, fit_params):
        pressed.append(tuple(offset))
        if offset[0] < -1.5:
            raise InputError("no rim over the face from here")
        return SimpleNamespace(offset_mm=tuple(offset), rank=lambda: (0, (offset[0] - 1.2) ** 2 + (offset[1] + 2.9) ** 2))

    monkeypatch.setattr(stock_fit, "_pressed", press)
    monkeypatch.setattr(stock_fit, "_refined_stock", lambda mask, size, params: (None, None))
    monkeypatch.setattr(stock_fit, "_placed", lambda mesh, face, offset: None)
    monkeypatch.setattr(stock_fit, "rim_zone", lambda *args: "zone")
    best = seated("nasal", "M", SimpleNamespace(axis=None, up=None))
    coarse = SEAT_STEPS_MM[0] * GRID
    fine = coarse[2] + SEAT_STEPS_MM[1] * GRID  # about (2, -2), the best of the coarse grid
    assert pressed == [tuple(o) for o in coarse] + [tuple(o) for o in fine if tuple(o) != tuple(coarse[2])]
    assert best.offset_mm == (1.0, -3.0)


def test_a_size_too_large_for_the_face_has_no_seat_and_is_named():
    """The L oronasal cushion on the mean face shrunk to 0.8: from no seat does its wall run all the
    way round the face, so it is not fitted (None); asked for alone, the comparison refuses in one
    line naming it; with every size tried, it is named among those with no seat (M too), the best
    chosen from the others (S)."""
    face = face_scaled(np.full(3, 0.8))
    assert seated("oronasal", "L", face) is None
    with pytest.raises(InputError, match=r"no oronasal stock size tried \(L\) finds its rim over this face at any seat"):
        compared_stock("oronasal", face, "L", asleep=False)
    every = compared_stock("oronasal", face, "best", asleep=False)
    record = every.record()
    assert every.not_seated == ("M", "L") and record["not_seated"] == ["M", "L"] and list(record["sizes_best_first"]) == ["S"]
    assert "best size by fit" in cushion_label({"stock_fitting": record}, "stock")
    assert "Stock sizes tried that find no seat on this face: M, L." in settings_line({"headgear_force_n": 2.0, "cpap_cmh2o": 10.0, "stock_fitting": record})


def test_a_design_sets_every_stock_size_beside_it_best_first(designed):
    """The design's stock comparison: every size of its mask seated within the seat grid's reach of
    the nasal bridge and strapped at no more than COMFORT_N, ranked (sealed first, then the lower
    peak), the best in every sleep state at its own force, all in fit.json's record."""
    _, d = designed
    sizes = d.stock.sizes
    assert sorted(f.size for f in sizes) == sorted(SIZES[d.contact.mask])
    assert [f.rank() for f in sizes] == sorted(f.rank() for f in sizes)
    assert all(np.abs(f.offset_mm).max() <= sum(SEAT_STEPS_MM) + 1e-9 and f.fit.force_n <= COMFORT_N + 1e-9 for f in sizes)
    assert all(f.fit.seal_force_n is not None and f.fit.force_n == pytest.approx(MARGIN * f.fit.seal_force_n) for f in sizes if f.sealed)
    record = d.stock.record()
    assert record["size"] == sizes[0].size and list(record["sizes_best_first"]) == [f.size for f in sizes]
    assert record["gauge_size"] == d.stock.gauge in ("S", "M", "L")
    assert [s.state for s in d.stock.states] == [s.state for s in d.states]
    gauge = d.stock.gauge != sizes[0].size  # the gauge's size beside the best, awake and asleep, where it is another
    assert ("stock_gauge" in d.fits) == gauge and all(("stock_gauge" in s.fits) == gauge for s in d.states)
    if gauge:
        assert d.fits["stock_gauge"] is next(f.fit for f in sizes if f.size == d.stock.gauge)


def test_with_no_worker_the_stock_sizes_press_on_the_faces_already_made(monkeypatch):
    """Asleep, with no worker (`at_once`), the best size and the gauge's both press on the sleep-state
    faces handed in (on a dense scan each moved face is hundreds of MB): no state face is made again,
    and every state reads the same as on faces made anew (the ICT mean face 10 % taller, whose
    gauge size is not its best). The work handed out `meanwhile` is called once, after the gauge's
    states are handed out and before the best's are pressed."""
    from cpapfit.evaluation import states
    from cpapfit.stock_fit import fitting_stock

    face = face_scaled(np.array([1.0, 1.1, 1.0]))
    asleep = states.state_faces(face, states.sleep_states("nasal"))
    made, make = [], states.state_face
    monkeypatch.setattr(states, "state_face", lambda *args: made.append(1) or make(*args))
    fitting = fitting_stock("nasal", face)  # its sizes seated once, for both comparisons
    order, press = [], stock_fit.stock_states
    monkeypatch.setattr(stock_fit, "stock_states", lambda *args, **kw: order.append(args[5] if len(args) > 5 else "stock") or press(*args, **kw))
    handed = fitting.comparison(faces=asleep, meanwhile=lambda: order.append("meanwhile"))
    assert order == ["stock_gauge", "meanwhile", "stock"]
    assert made == [] and handed.states and handed.gauge_states
    anew = fitting.comparison()
    assert made
    for ours, theirs in ((handed.states, anew.states), (handed.gauge_states, anew.gauge_states)):
        assert [s.state for s in ours] == [s.state for s in theirs]
        for a, b in zip(ours, theirs):
            assert a.fits.keys() == b.fits.keys()
            assert all(a.fits[k].summary() == b.fits[k].summary() for k in a.fits)


@pytest.mark.parametrize("offset", [(0.0, 0.0), (2.0, -2.0), (-1.0, 3.0)])
def test_the_rays_the_ceiling_spares_change_no_rim_point(monkeypatch, offset):
    """`rim_in` casts rays from the wall higher than SURE_MM over its sector's lowest only where the
    skin's ceiling (`evaluation.ceiling`) says they could touch first: the stock nasal M cushion,
    moved across the axis over a face whose scan is not its registered template, finds the same rim
    to the bit as casting from every vertex of the band."""
    scan = face_scaled(np.array([1.06, 0.95, 1.12])).scan
    face = Face(scan, trimesh.Trimesh(mean_face(), load_template().faces, process=False), np.array([0.0, 0.0, 1.0]),
                np.array([0.0, 1.0, 0.0]))
    mesh, thickness = _refined_stock("nasal", "M", CushionParams())
    across = trimesh.transformations.translation_matrix(np.asarray(offset) @ rim.in_plane(face.axis, face.up))
    zone = rim.rim_zone(_placed(mesh, face, np.zeros(2)), face.axis, face.up, thickness).moved(across)
    spared = rim.rim_in(zone, face.scan, face.registered, face.axis, face.up)
    monkeypatch.setattr(rim, "SURE_MM", rim.RIM_BAND_MM)
    every = rim.rim_in(zone, face.scan, face.registered, face.axis, face.up)
    for name in every.__dataclass_fields__:
        assert np.array_equal(np.asarray(getattr(spared, name)), np.asarray(getattr(every, name)), equal_nan=True), name
