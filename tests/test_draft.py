"""Demoulding analysis: draft angles on shapes whose draft is known, and on a designed cushion's mould."""

import numpy as np
import pytest
import trimesh

from cpapfit.fabrication.draft import MAX_BELOW_MIN, MAX_UNDERCUT, MIN_DRAFT_DEG, draft, draft_angles
from cpapfit.fabrication.mould import moulding_faces
from cpapfit.fabrication.parting import AWAY_MM, HeightField, between, under

UP = np.array([0.0, 0.0, 1.0])


def frustum(taper_deg: float, height: float = 20.0, radius: float = 10.0) -> trimesh.Trimesh:
    """A closed round frustum along +z whose side leans in by `taper_deg` as it rises."""
    top = radius - height * np.tan(np.radians(taper_deg))
    profile = [[0.0, 0.0], [radius, 0.0], [top, height], [0.0, height]]
    return trimesh.creation.revolve(profile, sections=256)


def test_a_tapered_core_drawn_out_towards_its_wide_end_has_its_taper_as_draft():
    """A core narrowing by 3 degrees as it goes into the cast (+z), like the inside of a cup."""
    mesh = frustum(3.0)
    angle, area = draft_angles(mesh.vertices, mesh.faces, -UP)
    side = np.abs(mesh.face_normals[:, 2]) < 0.99
    assert angle[side] == pytest.approx(3.0, abs=0.01)
    assert angle[mesh.face_normals[:, 2] > 0.99] == pytest.approx(90.0)  # its tip comes straight off the cast
    assert area.sum() == pytest.approx(mesh.area)
    d = draft(mesh.vertices, mesh.faces[side], -UP)
    assert d.below_min_fraction == 0.0 and d.undercut_fraction == 0.0 and d.min_draft_deg == pytest.approx(3.0, abs=0.01)


def test_the_same_core_drawn_towards_its_narrow_end_is_all_undercut():
    mesh = frustum(3.0)
    side = np.abs(mesh.face_normals[:, 2]) < 0.99
    d = draft(mesh.vertices, mesh.faces[side], UP)
    assert d.undercut_fraction == pytest.approx(1.0) and d.min_draft_deg == pytest.approx(-3.0, abs=0.01)


def test_straight_walls_have_no_draft_but_no_undercut():
    box = trimesh.creation.box((20.0, 10.0, 30.0))
    walls = np.abs(box.face_normals[:, 2]) < 0.5
    d = draft(box.vertices, box.faces[walls], UP)
    assert d.below_min_fraction == 1.0 and d.undercut_fraction == 0.0 and abs(d.min_draft_deg) < 1e-9
    half = draft(*_with_draft(0.5 * MIN_DRAFT_DEG), -UP)  # a shallow taper is flagged, not undercut
    assert half.below_min_fraction == 1.0 and half.undercut_fraction == 0.0


def _with_draft(taper_deg: float):
    mesh = frustum(taper_deg)
    return mesh.vertices, mesh.faces[np.abs(mesh.face_normals[:, 2]) < 0.99]


def test_moulding_faces_are_those_touching_the_cast():
    """A box mould around a box cast: its five inner walls touch the cast, the outside does not."""
    cast = trimesh.creation.box((10.0, 10.0, 10.0))
    mould = trimesh.creation.box((20.0, 20.0, 20.0)).difference(cast.apply_translation([0, 0, 5.0 + 1e-9]))
    faces = moulding_faces(mould, cast)
    assert trimesh.Trimesh(mould.vertices, faces).area == pytest.approx(5 * 100.0, rel=1e-6)


def test_designed_mould_parts_report_their_draft(designed):
    """Every face of the cushion is moulded by exactly one part: the parts' moulding areas add up
    to the cushion's surface; each part has a pull direction and fractions in [0, 1]. The outer
    parts, each in one piece, have draft: at most 5 % of each one's moulding area undercut, at
    least 95 % with 1 degree or more."""
    _, d = designed
    drafts = d.mould_draft
    assert set(drafts) == {"mould_left", "mould_right", "mould_face", "mould_core"}
    assert sum(x.area_mm2 for x in drafts.values()) == pytest.approx(d.solid.area, rel=0.01)
    for x in drafts.values():
        assert 0.0 <= x.undercut_fraction <= x.below_min_fraction <= 1.0 and x.pull_name
    assert drafts["mould_left"].pull @ drafts["mould_right"].pull == pytest.approx(-1.0)
    assert drafts["mould_face"].pull @ d.cushion.axis == pytest.approx(-1.0)
    for name in ("mould_left", "mould_right", "mould_face"):
        x = drafts[name]
        assert x.meets_target and x.undercut_fraction <= MAX_UNDERCUT and x.below_min_fraction <= MAX_BELOW_MIN, (name, x.record())
        assert d.mould_parts[name].body_count == 1, name


def test_a_height_field_bounds_a_closed_solid_of_the_volume_under_its_lid():
    b, c = np.arange(0.0, 10.5, 1.0), np.arange(0.0, 6.5, 1.0)
    h = 0.3 * b[:, None] - 0.2 * c[None, :] + 1.0  # a plane: the piecewise-linear surface is exact
    solid = HeightField(np.eye(3), b, c, h).solid(far=8.0)
    assert solid.is_watertight and solid.is_winding_consistent
    assert solid.volume == pytest.approx((8.0 - h.mean()) * 10.0 * 6.0, rel=1e-9)


def test_the_parting_between_two_halves_runs_through_the_silhouette():
    """A sphere split along x: the parting surface lies at its equator (x = 0) wherever rays meet it, and beside it."""
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=10.0)
    parting = between(sphere, np.eye(3), np.full(3, -12.0), np.full(3, 12.0))
    assert np.abs(parting.h).max() < 0.05


def test_the_face_plate_takes_only_an_underside_facing_its_pull():
    """A flat underside facing straight down is taken, midway through the cast's layer; one leaning
    80 degrees from the pull is left to the parts around."""
    lo, hi = np.array([-2.0, -15.0, -15.0]), np.array([12.0, 15.0, 15.0])
    slab = trimesh.creation.box((10.0, 20.0, 20.0)).apply_translation((5.0, 0.0, 0.0))  # along x (the pull's axis): 0 to 10
    flat = under(slab, np.eye(3), lo, hi)
    B, C = np.meshgrid(flat.b, flat.c, indexing="ij")
    beneath = (np.abs(B) < 8.0) & (np.abs(C) < 8.0)
    assert flat.h[beneath] == pytest.approx(5.0) and (flat.h[(np.abs(B) > 11.0) | (np.abs(C) > 11.0)] == lo[0] - AWAY_MM).all()
    leaning = under(slab.copy().apply_transform(trimesh.transformations.rotation_matrix(np.radians(80.0), UP)), np.eye(3), lo, hi)
    assert (leaning.h == lo[0] - AWAY_MM).all()
