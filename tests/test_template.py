import numpy as np
import pytest
from scipy.spatial import cKDTree

from cpapfit.template import MASKS, N_LANDMARKS, canonical_face, load_template, refined_template


@pytest.fixture(scope="module")
def template():
    return load_template()


def test_the_shipped_template_is_the_one_refined_afresh(template):
    """The shipped template (`tools/build_refined_template.py`) is the one `refined_template` makes now
    from the canonical face: the same vertices to the bit, triangles, mirror pairs, features and
    contact regions (curves, bands, their geodesic distances to the bit)."""
    fresh = refined_template()
    for name in ("vertices", "faces", "mirror"):
        shipped, made = getattr(template, name), getattr(fresh, name)
        assert shipped.dtype == made.dtype and np.array_equal(shipped, made), name
    assert list(template.features) == list(fresh.features)
    assert all(np.array_equal(template.features[k], fresh.features[k]) for k in fresh.features)
    for mask in MASKS:
        shipped, made = template.regions[mask], fresh.regions[mask]
        assert (shipped.name, shipped.half_width_mm) == (made.name, made.half_width_mm)
        assert all(np.array_equal(getattr(shipped, k), getattr(made, k)) for k in ("curve", "band", "distance")), mask


def test_refined_to_about_30000_vertices_in_mm(template):
    assert 25_000 <= len(template.vertices) <= 36_000
    height = np.ptp(template.vertices[:, 1])
    assert 150 <= height <= 220  # forehead to chin, mm


def test_first_468_vertices_are_the_landmarks(template):
    coarse, _ = canonical_face()
    moved = np.linalg.norm(template.vertices[:N_LANDMARKS] - coarse, axis=1)
    assert np.median(moved) < 1.5 and moved.max() < 4.0  # Loop smoothing moves them by ~1 mm


def test_known_landmarks_sit_where_they_should(template):
    v = template.vertices
    nose_tip, r_eye, l_eye, r_mouth, l_mouth = v[1], v[33], v[263], v[61], v[291]
    assert np.linalg.norm(nose_tip - v[np.argmax(v[:, 2])]) < 5.0  # the most prominent point
    assert r_eye[0] < -35 and l_eye[0] > 35  # subject's right is -x
    assert 80 <= np.linalg.norm(l_eye - r_eye) <= 100  # outer canthal distance, adults
    assert 40 <= np.linalg.norm(l_mouth - r_mouth) <= 60  # mouth width
    assert 25 <= r_eye[1] - nose_tip[1] <= 50 and 20 <= nose_tip[1] - r_mouth[1] <= 40
    for a, b in ((33, 263), (61, 291)):
        assert abs(v[a, 0] + v[b, 0]) < 0.5 and abs(v[a, 1] - v[b, 1]) < 0.5  # left-right symmetric


@pytest.mark.parametrize("mask", MASKS)
def test_contact_curve_is_a_closed_loop_of_edges(template, mask):
    region = template.regions[mask]
    curve = region.curve
    assert len(np.unique(curve)) == len(curve)  # simple: no vertex twice
    edges = {tuple(sorted(e)) for e in template.mesh().edges_unique.tolist()}
    steps = zip(curve, np.roll(curve, -1))
    assert all(tuple(sorted((int(a), int(b)))) in edges for a, b in steps)  # closed, along mesh edges
    assert set(curve.tolist()) <= set(region.band.tolist())


@pytest.mark.parametrize("mask,width,height", [("nasal", (35, 60), (35, 60)), ("oronasal", (65, 100), (80, 115))])
def test_contact_curves_have_adult_mask_sizes(template, mask, width, height):
    pts = template.vertices[template.regions[mask].curve]
    assert width[0] <= np.ptp(pts[:, 0]) <= width[1]
    assert height[0] <= np.ptp(pts[:, 1]) <= height[1]


@pytest.mark.parametrize("mask", MASKS)
def test_contact_regions_are_symmetric_and_enclose_the_nose(template, mask):
    region = template.regions[mask]
    band = template.vertices[region.band]
    mirrored = band * [-1, 1, 1]
    gap, _ = cKDTree(band).query(mirrored)
    assert np.percentile(gap, 95) < 2.0  # the band is left-right symmetric within 2 mm
    nose_tip = template.vertices[1]
    curve = template.vertices[region.curve]
    assert curve[:, 0].min() < nose_tip[0] < curve[:, 0].max()
    assert curve[:, 1].min() < nose_tip[1] < curve[:, 1].max()
    assert region.distance.max() <= region.half_width_mm + 1e-9
    lower_lip, upper_lip_top = template.vertices[17], template.vertices[0]
    if mask == "oronasal":  # the mouth is inside the seal
        assert curve[:, 1].min() < lower_lip[1] - 5
    else:  # a nasal mask seals above the upper lip's red margin
        assert curve[:, 1].min() > upper_lip_top[1]
