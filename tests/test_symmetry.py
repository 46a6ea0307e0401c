"""The face's plane of symmetry read off a scan, the template's mirror pairs, and the mirror term."""

import numpy as np
from scipy.spatial.transform import Rotation

from cpapfit.align.symmetry import Plane, mirror_pairs, mirror_term, plane_of_pairs, symmetry_plane
from cpapfit.rims import boundary_vertices
from cpapfit.template import load_template

TEMPLATE = load_template()
TURN = Rotation.from_euler("xyz", [10.0, -25.0, 5.0], degrees=True)
SHIFT = np.array([30.0, -20.0, 550.0])


def moved(points: np.ndarray) -> np.ndarray:
    return TURN.apply(points) + SHIFT


def truth() -> Plane:
    """The template's midline plane (x = 0) after the move."""
    normal = TURN.apply([1.0, 0.0, 0.0])
    return Plane(normal, float(normal @ SHIFT))


def apart(a: Plane, b: Plane, at: np.ndarray) -> tuple[float, float]:
    """The angle (deg) between two planes and their distance (mm) apart at a point."""
    sign = np.sign(a.normal @ b.normal)
    return np.degrees(np.arccos(min(1.0, abs(a.normal @ b.normal)))), abs((at @ a.normal - a.offset) - sign * (at @ b.normal - b.offset))


def test_template_mirror_pairs_are_exact():
    m = TEMPLATE.mirror
    assert np.array_equal(m[m], np.arange(len(m)))
    assert np.abs(TEMPLATE.vertices[m] - TEMPLATE.vertices * [-1.0, 1.0, 1.0]).max() < 1e-9
    assert np.all((m == np.arange(len(m))) == (np.abs(TEMPLATE.vertices[:, 0]) < 1e-9))


def test_a_surface_seen_from_one_side_gives_its_plane_of_symmetry():
    """The template's surface moved and turned, a third of one side cut away (a turned head: the cut
    and the face's outline are its rims), the search begun 4 deg and 4 mm off: the plane is found
    within 0.05 deg and 0.05 mm at the nose tip."""
    mesh = TEMPLATE.mesh()
    keep = TEMPLATE.vertices[:, 0] < 25.0
    points, normals = moved(TEMPLATE.vertices[keep]), TURN.apply(mesh.vertex_normals[keep])
    tilt = Rotation.from_rotvec(np.radians(4.0) * np.array([0.0, 0.6, 0.8])).apply(truth().normal)
    start = Plane(tilt, float(tilt @ SHIFT) + 4.0)
    tip = moved(TEMPLATE.vertices[4:5])[0]
    assert apart(start, truth(), tip)[1] > 3.0
    index = np.cumsum(keep) - 1
    rims = boundary_vertices(TEMPLATE.vertices[keep], index[mesh.faces[keep[mesh.faces].all(axis=1)]])  # the cut is a rim
    angle, gap = apart(symmetry_plane(points, normals, rims, start), truth(), tip)
    assert angle <= 0.05 and gap <= 0.05


def test_plane_of_pairs_of_a_moved_template_is_its_midline():
    angle, gap = apart(plane_of_pairs(moved(TEMPLATE.vertices), TEMPLATE.mirror), truth(), SHIFT)
    assert angle < 1e-6 and gap < 1e-6


def test_mirror_term_is_the_sum_of_squared_mirror_gaps():
    """u^T across u - 2 u . across_rhs + 4 c^2 (pairs) + v^T along v over both in-plane coordinates
    equals sum over pairs |reflect(p_i) - p_j|^2, for any points; zero for a symmetric face."""
    plane = truth()
    term = mirror_term(mirror_pairs(TEMPLATE.mirror), plane)
    pairs = np.arange(len(TEMPLATE.mirror)) <= TEMPLATE.mirror

    def energy(p: np.ndarray) -> float:
        f = p @ term.frame.T
        u, v = f[:, 0], f[:, 1:]
        const = 4.0 * plane.offset**2 * pairs.sum()
        return float(u @ (term.across @ u) - 2.0 * u @ term.across_rhs + const + np.sum(v * (term.along @ v)))

    p = moved(TEMPLATE.vertices) + np.random.default_rng(0).normal(0.0, 1.0, TEMPLATE.vertices.shape)
    i = np.flatnonzero(pairs)
    direct = np.sum((plane.reflect(p[i]) - p[TEMPLATE.mirror[i]]) ** 2)
    assert abs(energy(p) - direct) <= 1e-6 * direct
    assert abs(energy(moved(TEMPLATE.vertices))) <= 1e-6 * direct
