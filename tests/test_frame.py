"""The mask's frame: the ISO 5356-1 cone measured on slices of the written STL, the vents against
their target curve, the cushion in its groove (also where its end flares out past the ring, as on a
large face), the airway closed but for the holes; the dead space's column integral on solids of
known volume, and the frame ring lowered where the cushion would hold too much air."""

import io
from dataclasses import replace

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from cpapfit.cushion.generic import contact_on, template_cushion
from cpapfit.cushion.solid import cushion_solid
from cpapfit.cushion.nurbs import FRAME_RING_MM
from cpapfit.fabrication.dead_space import CUSHION_SHARE, _inside, ring_clearance, volume_in_front
from cpapfit.thresholds import DEAD_SPACE_LIMIT_ML
from cpapfit.fabrication.files import check_closed, stl_bytes
from cpapfit.solids import to_manifold
from cpapfit.fabrication.frame import CONE_MM, build_frame, cone_diameter_mm, mask_frame, sliced_diameters
from cpapfit.template import load_template
from cpapfit.fabrication.vents import TARGET_CMH2O, TARGET_L_MIN


FLARE = 1.15  # the face's side of the cushion widened about the axis, its ring kept: the end comes in from outside the ring


def flared(mask: str):
    """The template's cushion with all but its frame ring widened FLARE times about the axis."""
    cushion = template_cushion(mask)
    centre = mask_frame(cushion)[:3, 3]
    rel = np.array(cushion.control[:, :-1]) - centre
    along = (rel @ cushion.axis)[..., None] * cushion.axis
    control = np.array(cushion.control)
    control[:, :-1] = centre + along + FLARE * (rel - along)
    return replace(cushion, control=control)


@pytest.fixture(scope="module", params=[("nasal", False), ("oronasal", False), ("oronasal", True)], ids=["nasal", "oronasal", "flared"])
def framed(request):
    """(cushion solid, Frame) of the cushion designed on the template (flared: `flared`)."""
    mask, flare = request.param
    cushion = flared(mask) if flare else template_cushion(mask)
    solid, _, _ = cushion_solid(cushion, contact_on(mask, load_template().mesh()).normals)
    return solid, build_frame(cushion, solid)


def test_the_written_cone_holds_the_standards_diameters_within_0_05_mm(framed):
    _, frame = framed
    stl = trimesh.load(io.BytesIO(stl_bytes(frame.mesh)), file_type="stl")  # float32, as a slicer reads it
    from_tip = np.array([0.5, 5.0, 10.0, 15.0, 20.0, CONE_MM - 0.5])
    measured = sliced_diameters(stl, frame.port_tip, frame.port_axis, from_tip)  # the cone's, around the bore's
    assert np.abs(measured - cone_diameter_mm(from_tip)).max() <= 0.05
    assert cone_diameter_mm(15.0) == pytest.approx(22.37, abs=0.001)


def test_the_frame_is_closed_with_a_hole_for_each_vent_valve_and_strap_slot(framed):
    solid, frame = framed
    assert check_closed(frame.mesh, "frame")["self_intersecting_edges"] == 0
    assert to_manifold(frame.mesh).genus() >= 1 + frame.holes  # the tube to the port, and each hole through it
    assert frame.holes == frame.vents.count + (frame.valve is not None) + 4
    flow = frame.vents.flow_l_min(TARGET_CMH2O)
    assert np.all(np.abs(flow / np.array(TARGET_L_MIN) - 1.0) <= 0.25)
    assert np.all(frame.vent_holes[:, 1] @ frame.port_axis > 0.3)  # out of the face
    side = np.cross(frame.port_axis, frame.anchors[0] - frame.anchors[3])
    assert np.all(np.abs(frame.vent_holes[:, 1] @ (side / np.linalg.norm(side))) < 0.5)  # not at a bed partner beside


def test_the_cushion_sits_in_its_groove_and_the_airway_is_closed(framed):
    solid, frame = framed
    fit = frame.assembly
    assert fit["interference_mm3"] < 0.01 and fit["airway_closed"] and fit["joined_genus"] == 1 + frame.holes and fit["pieces"] == 1
    near, _ = cKDTree(frame.mesh.vertices).query(solid.vertices)
    touching = solid.vertices[near < 1e-3]  # the cushion's corners the groove's faces share: where it holds the cushion
    across = touching - (touching @ frame.port_axis)[:, None] * frame.port_axis
    centre = across.mean(axis=0)
    basis = np.linalg.svd(np.eye(3) - np.outer(frame.port_axis, frame.port_axis))[0][:, :2]
    angle = np.degrees(np.arctan2(*((across - centre) @ basis).T[::-1]))
    assert len(np.unique(np.floor(angle / 5.0))) == 72  # held all round, in every 5 degrees
    anchors = frame.anchors - frame.anchors.mean(axis=0)
    assert np.linalg.norm(anchors.sum(axis=0)) < 1.0  # symmetric about the axis: the straps' pull along it


def test_volume_in_front_of_a_skin_on_solids_of_known_volume():
    axis = np.array([0.0, 0.0, 1.0])
    skin = trimesh.creation.box([200.0, 200.0, 1.0])
    skin.apply_translation([0.0, 0.0, 4.5])  # its front at z = 5
    assert volume_in_front(trimesh.creation.box([10.0, 20.0, 30.0]), skin, axis) == pytest.approx(2000.0, rel=1e-3)
    sphere = trimesh.creation.icosphere(4, 10.0)
    below = skin.copy()
    below.apply_translation([0.0, 0.0, -100.0])
    assert volume_in_front(sphere, below, axis) == pytest.approx(sphere.volume, rel=0.01)
    cap = np.pi * 5.0**2 * (3 * 10.0 - 5.0) / 3  # the sphere above z = 5
    assert volume_in_front(sphere, skin, axis) == pytest.approx(cap, rel=0.02)


def test_the_ring_comes_down_where_the_cushion_holds_too_much_air(monkeypatch):
    cushion, skin = template_cushion("oronasal"), load_template().mesh()
    assert ring_clearance(cushion, skin) == cushion.params.frame_clearance_mm  # the template's face: within the limit
    inside_ml = volume_in_front(_inside(cushion), skin, cushion.axis) / 1000.0
    monkeypatch.setitem(DEAD_SPACE_LIMIT_ML, "oronasal", (inside_ml - 15.0) / CUSHION_SHARE)  # a limit the cushion's inside is 15 ml over
    lowered = ring_clearance(cushion, skin)
    a, b = np.array(FRAME_RING_MM["oronasal"]) / 2
    assert lowered == pytest.approx(cushion.params.frame_clearance_mm - 15000.0 / (np.pi * a * b), abs=1e-6)
    again = template_cushion("oronasal", replace(cushion.params, frame_clearance_mm=lowered))
    assert volume_in_front(_inside(again), skin, cushion.axis) / 1000.0 == pytest.approx(inside_ml - 15.0, abs=3.0)
