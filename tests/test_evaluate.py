"""Fit evaluation: the physics on cases with known answers, then custom vs generic on synthetic subjects."""

from types import SimpleNamespace

import numpy as np
import pytest
import trimesh
from scipy.spatial import Delaunay

from cpapfit.errors import InputError
from cpapfit.cushion import compensation
from cpapfit.cushion.compensation import corrected, pressed
from cpapfit.cushion.envelope import PEAK_MARGIN_KPA, headgear_force
from cpapfit.evaluation.ceiling import ceilings
from cpapfit.evaluation.fit import MAX_PRELOAD_MM, STEP_MM, FitParams, fit_cushion, fit_rim, peak_force, refined_preload, window_force
from cpapfit.evaluation.leak import leak_l_min
from cpapfit.evaluation.mechanics import Flaps, least_force_n, press
from cpapfit.evaluation.membrane import ROOT_MM
from cpapfit.evaluation import rim
from cpapfit.evaluation.rim import RimContact, RimZone, find_rim, rim_in, seal_lengths, _nearest_skin, _skin_below, _skin_planes
from cpapfit.evaluation.tissue import stiffness
from cpapfit.pipeline import face_for

RING_MM = 30.0  # radius of the flat test rim
K = 256
AREA = 5.0 * 2 * np.pi * RING_MM / K  # flange width x arc length per point, mm^2


def ring_uv():
    t = 2 * np.pi * np.arange(K) / K
    return RING_MM * np.column_stack([np.cos(t), np.sin(t)])


def flat(clearance=None, k=1.0, force_n=10.0, cpap_kpa=0.0, uv=None):
    """A flat rim on a flat face: K points, unit |cos|, uniform stiffness k (kPa/mm)."""
    uv = ring_uv() if uv is None else uv
    clearance = np.zeros(K) if clearance is None else clearance
    return press(clearance, np.ones(K), np.full(K, AREA), np.full(K, k), uv, np.pi * RING_MM**2, force_n, cpap_kpa)


def test_flat_rim_on_flat_face_presses_force_over_contact_area():
    pressed = flat(force_n=10.0)
    expected_kpa = 10.0 / (K * AREA) * 1e3  # N / mm^2 -> kPa
    assert pressed.pressure_kpa == pytest.approx(np.full(K, expected_kpa), rel=1e-6)
    with_cpap = flat(force_n=10.0, cpap_kpa=1.0)  # 10 cmH2O ~ 1 kPa over the sealed disc pushes back
    expected_kpa = (10.0 - 1.0 * np.pi * RING_MM**2 * 1e-3) / (K * AREA) * 1e3
    assert with_cpap.pressure_kpa == pytest.approx(np.full(K, expected_kpa), rel=1e-6)


def test_doubling_stiffness_halves_indentation():
    soft, stiff = flat(k=1.0), flat(k=2.0)
    assert stiff.shift_mm == pytest.approx(soft.shift_mm / 2, rel=1e-6)
    assert stiff.pressure_kpa == pytest.approx(soft.pressure_kpa, rel=1e-6)  # same force, same area


def test_a_sloping_face_tilts_the_mask_until_it_presses_evenly():
    uv = ring_uv()
    pressed = flat(clearance=0.05 * uv[:, 0], uv=uv)  # the face falls away 5 % towards +u
    assert np.degrees(np.arctan(pressed.tilt[0])) == pytest.approx(np.degrees(np.arctan(0.05)), abs=0.01)
    assert pressed.pressure_kpa.std() < 1e-6 * pressed.pressure_kpa.mean()


def test_moments_balance_on_an_uneven_face():
    rng = np.random.default_rng(3)
    uv, k = ring_uv(), rng.uniform(0.5, 3.0, K)
    clearance = rng.uniform(0.0, 1.0, K)
    pressed = press(clearance, np.ones(K), np.full(K, AREA), k, uv, np.pi * RING_MM**2, 8.0, 0.0)
    load = pressed.pressure_kpa * AREA * 1e-3  # N at each point
    assert load.sum() == pytest.approx(8.0, rel=1e-6)
    assert np.abs(load @ (uv - uv.mean(axis=0))).max() < 1e-6 * 8.0 * RING_MM  # no net moment about the centre


def test_too_little_force_lifts_the_mask_and_opens_the_whole_seal():
    pressed = flat(force_n=1.0, cpap_kpa=1.0)  # CPAP load 2.8 N > 1 N of headgear
    assert pressed.lifted and (pressed.pressure_kpa == 0).all() and (pressed.opening_mm > 0).all()


def test_uniform_gap_leaks_the_analytic_lubrication_flow():
    h_mm, width_mm, dp_kpa = 0.05, 5.0, 10 * 0.0980665
    ds = np.full(K, 2 * np.pi * RING_MM / K)
    mu = 1.8e-5  # Pa s, air
    analytic = (h_mm * 1e-3) ** 3 * dp_kpa * 1e3 * (2 * np.pi * RING_MM * 1e-3) / (12 * mu * width_mm * 1e-3) * 6e4
    assert leak_l_min(np.full(K, h_mm), ds, width_mm, dp_kpa).sum() == pytest.approx(analytic, rel=1e-9)
    wide = leak_l_min(np.full(K, 2.0), ds, width_mm, dp_kpa).sum()  # 2 mm: orifice-limited, not h^3
    orifice = 0.6 * 2.0e-3 * 2 * np.pi * RING_MM * 1e-3 * np.sqrt(2 * dp_kpa * 1e3 / 1.2) * 6e4
    assert wide == pytest.approx(orifice, rel=1e-9)


def test_rim_of_a_flat_ring_on_a_plane():
    """find_rim on a plane: every sector found, clearance the ring's height, sealed area the disc."""
    plane = trimesh.creation.box((200, 200, 2)).apply_translation((0, 0, -1))  # top face at z = 0
    ring = trimesh.creation.annulus(RING_MM, RING_MM + 6, 10).apply_translation((0, 0, 5 + 3))  # bottom at z = 3
    rim = find_rim(ring, plane, plane, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    assert rim.covered.all()
    assert rim.clearance == pytest.approx(np.full(256, 3.0), abs=1e-6)
    assert rim.sealed_area_mm2 == pytest.approx(np.pi * RING_MM**2, rel=0.01)
    assert rim.ds.sum() == pytest.approx(2 * np.pi * RING_MM, rel=0.01)


def test_a_rim_jumping_between_its_flanges_edges_seals_no_longer_a_stretch():
    """A rim's seal length: a smooth loop's own length (an ellipse 80 x 60 mm, within 0.5 %); where
    the sectors' rim points jump between a flange's inner and outer edge (5 mm apart, every other
    sector over 20 of 256) the seal is not 80 mm longer for it (within 2.5 % of the smooth rim)."""
    t = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    a, b = 40.0, 30.0
    ellipse = np.column_stack([a * np.cos(t), b * np.sin(t), np.zeros_like(t)])
    h = ((a - b) / (a + b)) ** 2
    assert seal_lengths(ellipse).sum() == pytest.approx(np.pi * (a + b) * (1 + 3 * h / (10 + np.sqrt(4 - 3 * h))), rel=0.005)
    circle = np.column_stack([RING_MM * np.cos(t), RING_MM * np.sin(t), np.zeros_like(t)])
    jumping = circle.copy()
    jumping[100:120:2] *= (RING_MM + 5.0) / RING_MM
    assert np.linalg.norm(np.diff(jumping, axis=0), axis=1).sum() > 2 * np.pi * RING_MM + 80  # point to point
    assert seal_lengths(jumping).sum() == pytest.approx(2 * np.pi * RING_MM, rel=0.025)


def test_the_preload_is_corrected_where_the_flanges_outer_edge_presses():
    """One pressing of the compensated cushion corrects each seal point's pre-load by its own
    sector's rim point, wherever across the 5 mm flange that lies: an outer edge 5 mm out pressing
    5 kPa lowers the pre-load there by the full step against the rest of the rim (pressing the
    target); a rim point 12 mm out, beyond the flange and NEAR_MM, corrects nothing."""
    t = np.linspace(0, 2 * np.pi, 128, endpoint=False)
    curve = np.column_stack([RING_MM * np.cos(t), RING_MM * np.sin(t), np.zeros_like(t)])
    s = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    radius = np.where(np.abs(np.angle(np.exp(1j * s))) < 0.3, RING_MM + 5.0, RING_MM)  # the outer edge around angle 0
    radius[np.abs(s - np.pi) < 0.3] = RING_MM + 12.0  # and a wall point far off the flange around angle pi
    points = np.column_stack([radius * np.cos(s), radius * np.sin(s), np.zeros_like(s)])
    rim = SimpleNamespace(points=points, covered=np.ones(256, dtype=bool), cos=np.ones(256), axis=np.array([0.0, 0.0, 1.0]))
    params = FitParams()
    pressure = np.where(radius > RING_MM, 5.0, params.target_kpa)
    fit = SimpleNamespace(rim=rim, stiffness=SimpleNamespace(effective=np.full(256, 0.9)), pressure_kpa=pressure, contact_width_mm=5.0)
    preload = refined_preload(np.zeros(128), curve, fit, 3.0, params)
    assert preload[0] == 0.0 and preload[64] == pytest.approx(STEP_MM, abs=0.05)


def dipped_ring() -> RimContact:
    """A flat rim of K points on a flat face, its first quarter standing 1 mm off the skin."""
    uv = ring_uv()
    points = np.column_stack([uv, np.zeros(K)])
    clearance = np.where(np.arange(K) < K // 4, 1.0, 0.0)
    zeros = np.zeros(K)
    return RimContact(points, points, clearance, np.ones(K), np.full(K, AREA / 5.0), uv, np.array([0.0, 0.0, 1.0]),
                      np.pi * RING_MM**2, zeros, zeros)


def window_share(rim: RimContact, k: np.ndarray, force_n: float, params: FitParams) -> float:
    """The share of `rim`'s points pressing within the safe window at `force_n` N (5 mm flange)."""
    p = press(rim.clearance, rim.cos, 5.0 * rim.ds, k, rim.uv, rim.sealed_area_mm2, force_n, params.cpap_kpa).pressure_kpa
    low, high = params.window_kpa
    return float(((p >= low) & (p <= high)).mean())


def test_the_window_force_is_the_least_that_keeps_the_most_of_the_rim_in_the_window():
    """The dipped ring: at the least force that holds it on, its raised quarter presses under the
    window; `window_force` raises the force, within its bounds, to the least of its steps at which
    the most of the rim lies in the window; with no room above its lower bound it keeps that."""
    rim, k, params = dipped_ring(), np.full(K, 0.9), FitParams()
    lo, hi = 3.0, 12.0
    force = window_force(rim, k, 5.0, params, lo, hi)
    assert window_share(rim, k, lo, params) < 0.8 and window_share(rim, k, force, params) == 1.0
    assert force == pytest.approx(min(f for f in np.linspace(lo, hi, 17) if window_share(rim, k, f, params) == 1.0))
    assert window_force(rim, k, 5.0, params, hi, lo) == hi


def test_the_headgear_force_seals_within_the_awake_peak_limit_and_is_raised_for_the_window():
    """`headgear_force` on the dipped ring (`most`: where its peak reaches the limit): the
    recommended force held to `most`; an awake seal force past `most` kept (sealing comes first);
    no force that seals awake, or a state no force seals, asks for `most`; a low recommended force
    raised to the least that puts the whole rim in the window."""
    rim, k, params = dipped_ring(), np.full(K, 0.9), FitParams()
    most = peak_force(rim, k, 5.0, params, params.capillary_kpa - PEAK_MARGIN_KPA)

    def awake(force_n, seal_n):
        return SimpleNamespace(rim=rim, stiffness=SimpleNamespace(effective=k), contact_width_mm=5.0, force_n=force_n, seal_force_n=seal_n)

    def state(seal_n):
        return SimpleNamespace(state=SimpleNamespace(cpap_cmh2o=None), fits={"custom": SimpleNamespace(seal_force_n=seal_n)})

    assert window_share(rim, k, 3.0, params) < 0.8 and 5.0 < most < 8.0
    assert headgear_force(awake(most + 2.0, 1.0), (), params) == pytest.approx(most)
    assert headgear_force(awake(3.0, most + 1.0), (), params) == pytest.approx(most + 1.0)
    assert headgear_force(awake(3.0, None), (), params) == pytest.approx(most)
    assert headgear_force(awake(3.0, 1.0), (state(None),), params) == pytest.approx(most)
    raised = headgear_force(awake(3.0, 1.0), (state(2.0),), params)
    assert 3.0 < raised <= most and window_share(rim, k, raised, params) == 1.0


def test_scan_behind_the_face_is_a_hole_and_scan_in_front_of_it_is_pressed_on():
    """The registered face a plane at z = 0; the scan the same plane except a patch under the rim
    6 mm behind it (a ray through a hole meets what lies behind) and one 6 mm in front of it (a
    template sunk into the face, or something on it): the first is not covered, the second is,
    with the rim 3 mm inside it."""
    from tests.test_cushion import grid_faces

    n = 161
    xy = np.stack(np.meshgrid(np.linspace(-40, 40, n), np.linspace(-40, 40, n)), -1).reshape(-1, 2)
    face = trimesh.Trimesh(np.column_stack([xy, np.zeros(len(xy))]), grid_faces(n), process=False)
    height = np.where(np.linalg.norm(xy - [RING_MM, 0.0], axis=1) < 5.0, -6.0, 0.0)
    height = np.where(np.linalg.norm(xy - [-RING_MM, 0.0], axis=1) < 5.0, 6.0, height)
    scan = trimesh.Trimesh(np.column_stack([xy, height]), grid_faces(n), process=False)
    ring = trimesh.creation.annulus(RING_MM, RING_MM + 6, 10).apply_translation((0, 0, 5 + 3))
    rim = find_rim(ring, scan, face, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    behind = np.linalg.norm(rim.points[:, :2] - [RING_MM, 0.0], axis=1) < 3.0
    front = np.linalg.norm(rim.points[:, :2] - [-RING_MM, 0.0], axis=1) < 3.0
    assert behind.any() and front.any()
    assert not rim.covered[behind].any()
    # 0.02: the points 2-3 mm from the step's wall read its slope into their skin's normal
    assert rim.covered[front].all() and rim.clearance[front] == pytest.approx(-3.0, abs=0.02)


@pytest.mark.parametrize("bottom, tall", [(-2.0, 1.5), (-0.5, 4.0)])
def test_a_rim_inside_the_scanned_skin_is_over_skin_however_deep_the_registered_face_reads_it(bottom, tall):
    """A rim pressed into a scanned plane where the registered face stands 10 mm in front of the
    scan over a patch (its overhang: the wing of the nose over the crease beside it): covered, as
    deep as it is pressed, not taken for a ray through a hole (12 mm behind the face); a ring all in
    the skin (2 mm deep), and one standing out of it (0.5 mm deep, 4 mm tall: its wall up to 3.5 mm
    above the skin under the overhang is not over a hole either, nor then the first to touch)."""
    from tests.test_cushion import grid_faces

    n = 161
    xy = np.stack(np.meshgrid(np.linspace(-40, 40, n), np.linspace(-40, 40, n)), -1).reshape(-1, 2)
    scan = trimesh.Trimesh(np.column_stack([xy, np.zeros(len(xy))]), grid_faces(n), process=False)
    height = np.where(np.linalg.norm(xy - [RING_MM, 0.0], axis=1) < 8.0, 10.0, 0.0)
    face = trimesh.Trimesh(np.column_stack([xy, height]), grid_faces(n), process=False)
    ring = trimesh.creation.annulus(RING_MM, RING_MM + 6, tall).apply_translation((0, 0, tall / 2 + bottom))
    rim = find_rim(ring, scan, face, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    under = np.linalg.norm(rim.points[:, :2] - [RING_MM, 0.0], axis=1) < 4.0
    assert under.any() and rim.covered.all()
    assert rim.clearance == pytest.approx(np.full(len(rim.clearance), bottom), abs=0.05)


def test_a_rim_past_the_edge_of_the_registered_face_over_scanned_skin_is_found_there():
    """A registered face 50 mm square under a ring of radius 30-36 mm, the scanned plane under all
    of it: the rim is found on the scan (every sector, clearance 3 mm), not refused for running
    off the registered face."""
    plane = trimesh.creation.box((200, 200, 2)).apply_translation((0, 0, -1))  # top face at z = 0
    face = trimesh.creation.box((50, 50, 2)).apply_translation((0, 0, -1))
    ring = trimesh.creation.annulus(RING_MM, RING_MM + 6, 10).apply_translation((0, 0, 5 + 3))  # bottom at z = 3
    rim = find_rim(ring, plane, face, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    assert rim.covered.all()
    assert rim.clearance == pytest.approx(np.full(len(rim.clearance), 3.0), abs=1e-6)


def test_a_rim_over_a_sparse_point_cloud_is_measured_to_its_skin_not_its_points():
    """A cloud of points 4 mm apart on the plane z = 0 (with its normals): rim points 0.2 mm above it,
    midway between points (2.8 mm from the nearest), are 0.2 mm off the skin; 9 mm above, 9 mm."""
    from cpapfit.evaluation.gap import rim_gap
    from cpapfit.scan import Scan

    grid = np.stack(np.meshgrid(np.arange(-40, 41, 4.0), np.arange(-40, 41, 4.0)), -1).reshape(-1, 2)
    cloud = Scan(np.column_stack([grid, np.zeros(len(grid))]), np.zeros((0, 3), dtype=np.int64), np.tile([0.0, 0.0, 1.0], (len(grid), 1)))
    midway = np.column_stack([grid[:40] + 2.0, np.full(40, 0.2)])
    assert rim_gap(midway, None, cloud, None).gap == pytest.approx(np.full(40, 0.2), abs=1e-9)
    assert rim_gap(midway + [0, 0, 8.8], None, cloud, None).gap.min() >= 9.0


def test_a_rim_over_a_clouds_sparse_patch_is_measured_to_its_skin_not_its_points():
    """The plane z = 0 sampled every 1 mm but, over a 24 mm square, only every 8 mm (a decimated
    mesh's vertices are sparse where the face is flat): rim points on the plane there, 5.7 mm from
    the nearest point, are on the skin (0 mm); 8 mm above it, at least 8 mm off."""
    from cpapfit.evaluation.gap import rim_gap
    from cpapfit.scan import Scan

    grid = np.stack(np.meshgrid(np.arange(-40, 41, 1.0), np.arange(-40, 41, 1.0)), -1).reshape(-1, 2)
    inside = (np.abs(grid) < 12).all(axis=1)
    grid = grid[~inside | (grid % 8 == 0).all(axis=1)]
    cloud = Scan(np.column_stack([grid, np.zeros(len(grid))]), np.zeros((0, 3), dtype=np.int64), np.tile([0.0, 0.0, 1.0], (len(grid), 1)))
    rim = np.array([[4.0, 4.0, 0.0], [-4.0, 4.0, 0.0], [4.0, -4.0, 0.0], [-4.0, -4.0, 0.0]])
    assert rim_gap(rim, None, cloud, None).gap == pytest.approx(np.zeros(4), abs=1e-9)
    assert rim_gap(rim + [0, 0, 8.0], None, cloud, None).gap.min() >= 8.0


def test_a_rim_over_a_mesh_is_measured_to_the_skin_under_its_flange_not_one_stray_sample():
    """The plane z = 0 sampled every 0.5 mm, every 8th sample along each row standing 0.8 mm up (stray
    samples): rim points on the plane right above those samples, 0.3 mm from the closest scan
    surface, lie within 0.01 mm of the skin under the flange; 2 mm above the plane, 2 mm."""
    from cpapfit.evaluation.gap import rim_gap
    from cpapfit.scan import Scan

    vertices, faces = grid_mesh(41, 0.5)
    i, j = np.meshgrid(np.arange(41), np.arange(41), indexing="ij")
    stray = (i % 8 == 4) & (j % 8 == 4)
    vertices[:, 2] = 0.8 * stray.ravel()
    scan = Scan(vertices, faces, np.tile([0.0, 0.0, 1.0], (len(vertices), 1)))
    surface = trimesh.Trimesh(vertices, faces, process=False)
    rim = vertices[stray.ravel()] * [1, 1, 0]
    assert trimesh.proximity.closest_point(surface, rim)[1].min() >= 0.3
    up = np.tile([0.0, 0.0, 1.0], (len(rim), 1))
    assert rim_gap(rim, up, scan, surface).gap.max() <= 0.01
    assert rim_gap(rim + [0, 0, 2], up, scan, surface).gap == pytest.approx(np.full(len(rim), 2.0), abs=0.01)


def grid_mesh(n: int, step: float) -> tuple[np.ndarray, np.ndarray]:
    """An n x n grid of points `step` mm apart on the plane z = 0, centred on the origin: (n*n, 3)
    vertices, row-major as np.meshgrid(indexing="ij"), and their (2 (n-1)^2, 3) triangles."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    vertices = np.column_stack([step * (i.ravel() - (n - 1) / 2), step * (j.ravel() - (n - 1) / 2), np.zeros(n * n)])
    corner = (i[:-1, :-1] * n + j[:-1, :-1]).ravel()
    return vertices, np.vstack([np.column_stack([corner, corner + n, corner + 1]), np.column_stack([corner + 1, corner + n, corner + n + 1])])


def test_a_rim_on_a_noisy_scans_skin_is_measured_to_the_skin_not_the_noise():
    """A cheek-like cylinder (radius 40 mm) sampled every 1 mm with depth noise of sigma 0.35 mm (a
    depth camera at 600 mm): rim points on the true skin read a median 0.1 mm and at most 0.35 mm
    from it (the median of seven ray hits on the noisy triangles: 0.42 mm), rim points 1 mm out
    1 +- 0.35 mm."""
    from cpapfit.evaluation.gap import rim_gap
    from cpapfit.scan import Scan

    vertices, faces = grid_mesh(61, 1.0)
    x = vertices[:, 0]
    vertices[:, 2] = np.sqrt(40.0**2 - x**2) - 40.0 + np.random.default_rng(0).normal(0.0, 0.35, len(x))
    noisy = trimesh.Trimesh(vertices, faces, process=False)
    t = np.linspace(-15.0, 15.0, 16)
    u, v = (a.ravel() for a in np.meshgrid(t, t))
    normals = np.column_stack([u / 40.0, np.zeros_like(u), np.sqrt(40.0**2 - u**2) / 40.0])
    skin = normals * 40.0 - [0.0, 0.0, 40.0] + np.column_stack([np.zeros_like(u), v, np.zeros_like(u)])
    scan = Scan(vertices, faces, noisy.vertex_normals)
    on_skin = rim_gap(skin, normals, scan, noisy).gap
    assert np.median(on_skin) <= 0.1 and on_skin.max() <= 0.35
    assert rim_gap(skin + normals, normals, scan, noisy).gap == pytest.approx(np.ones(len(u)), abs=0.35)


def test_a_rim_over_a_hole_is_not_covered_by_a_stray_point_in_it():
    """A plane with a 20 mm square hole holding nine points in no triangle (stray depth samples): the
    rim over the hole is not over scanned skin; the rim over the plane is, 1 mm above it."""
    from cpapfit.evaluation.gap import rim_gap
    from cpapfit.scan import Scan

    plane = trimesh.creation.box((100, 100, 2)).apply_translation((0, 0, -1))
    plane = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(plane.vertices, plane.faces, 2.0), process=False)
    keep = ~(np.abs(plane.triangles_center[:, :2]) < 10).all(axis=1)
    stray = np.column_stack([np.stack(np.meshgrid([-0.5, 0, 0.5], [-0.5, 0, 0.5]), -1).reshape(-1, 2), np.zeros(9)])
    vertices = np.vstack([plane.vertices, stray])
    scan = Scan(vertices, plane.faces[keep], np.vstack([plane.vertex_normals, np.tile([0.0, 0.0, 1.0], (9, 1))]))
    rim = np.array([[0.0, 0.0, 1.0], [30.0, 30.0, 1.0]])
    gap = rim_gap(rim, np.tile([0.0, 0.0, 1.0], (2, 1)), scan, trimesh.Trimesh(vertices, plane.faces[keep], process=False))
    assert gap.covered.tolist() == [False, True]
    assert gap.gap[1] == pytest.approx(1.0, abs=1e-6)


def test_a_rim_over_no_scanned_skin_is_refused_in_words():
    """A cushion whose rim lies over none of the scan (placed off the face, or in another frame)."""
    plane = trimesh.creation.box((200, 200, 2)).apply_translation((0, 0, -1))
    elsewhere = trimesh.creation.box((10, 10, 2)).apply_translation((150, 150, -1))
    ring = trimesh.creation.annulus(RING_MM, RING_MM + 6, 10).apply_translation((0, 0, 8))
    with pytest.raises(InputError, match="0 % of the cushion's rim lies over scanned skin"):
        find_rim(ring, elsewhere, plane, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))


@pytest.mark.parametrize("inside_out", [False, True])
def test_a_rim_under_an_overhang_is_measured_to_the_skin_below_it_not_to_the_overhang(inside_out):
    """Skin: the top of a slab (z = 0) with a ledge standing 6-10 mm over half of it (the wing of a
    nose over the groove beside it). Under the ledge, a rim point 2 mm above the skin reads +2 mm and
    one pressed 1.5 mm into it -1.5 mm (not 8 and 11.5 mm inside the ledge); the same with every
    triangle wound inside out."""
    slab = trimesh.creation.box((80, 80, 10)).apply_translation((0, 0, -5))
    ledge = trimesh.creation.box((40, 80, 4)).apply_translation((-20, 0, 8))
    skin = trimesh.util.concatenate([slab, ledge])
    if inside_out:
        skin = trimesh.Trimesh(skin.vertices, skin.faces[:, ::-1], process=False)
    points = np.array([[-15.0, 0.0, 2.0], [-15.0, 10.0, -1.5], [15.0, 0.0, 2.0], [15.0, 10.0, -1.5]])
    clearance, _ = _skin_below(points, skin, np.array([0.0, 0.0, 1.0]))
    assert clearance == pytest.approx([2.0, -1.5, 2.0, -1.5], abs=1e-6)


def test_one_stray_triangle_of_a_scan_does_not_lift_the_skin_under_the_rim():
    """A flat scan on a 0.5 mm grid with one vertex under the rim pulled 3 mm out (a torn edge's
    spike): the rim's clearance there is still the ring's height (the median under the flange)."""
    from tests.test_cushion import grid_faces

    n = 161
    xy = np.stack(np.meshgrid(np.linspace(-40, 40, n), np.linspace(-40, 40, n)), -1).reshape(-1, 2)
    plane = trimesh.Trimesh(np.column_stack([xy, np.zeros(len(xy))]), grid_faces(n), process=False)
    ring = trimesh.creation.annulus(RING_MM, RING_MM + 6, 10).apply_translation((0, 0, 5 + 3))
    axis, up = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    under = find_rim(ring, plane, plane, axis, up).points[40, :2]  # a rim point, and the scan vertex under it
    spike = np.argmin(np.linalg.norm(xy - under, axis=1))
    assert np.linalg.norm(xy[spike] - under) < 0.3
    height = np.zeros(len(xy))
    height[spike] = 3.0
    rim = find_rim(ring, trimesh.Trimesh(np.column_stack([xy, height]), grid_faces(n), process=False), plane, axis, up)
    assert rim.covered.all()
    assert rim.clearance == pytest.approx(np.full(256, 3.0), abs=0.01)


def test_a_rim_point_beside_a_ridge_is_pressed_by_its_distance_from_the_skin():
    """Skin: a ridge 6 mm high whose flank falls steeply to a flat floor (the wing of the nose beside
    the cheek), a height field on a 0.25 mm grid; rim points pressed 1-3 mm into it under the flank's
    shoulder and at its foot. Along the axis, the skin's tangent plane above a point puts it 2 mm
    deeper under the shoulder than it is, and 0.6 mm shallower at the foot; the rim's clearance times
    its |cos| (its depth as the fit model presses it) is its distance from the skin within 0.05 mm."""
    from tests.test_cushion import grid_faces

    def ridge(x):
        return 6.0 / (1.0 + np.exp((np.abs(x) - 5.0) / 0.6))

    n = 121
    xy = np.stack(np.meshgrid(np.linspace(-15, 15, n), np.linspace(-15, 15, n)), -1).reshape(-1, 2)
    skin = trimesh.Trimesh(np.column_stack([xy, ridge(xy[:, 0])]), grid_faces(n), process=False)
    points = np.array([[4.0, 0.0, -1.0], [4.5, 0.0, 1.0], [5.0, 0.0, -2.0], [5.5, 0.0, -2.0]])
    profile = np.linspace(-15, 15, 300001)
    exact = np.array([np.hypot(profile - x, ridge(profile) - z).min() for x, _, z in points])
    axis = np.array([0.0, 0.0, 1.0])
    clearance, under = _skin_below(points, skin, axis)
    cos = np.abs(_skin_planes(under, skin)[0] @ axis)
    assert -clearance * cos - exact == pytest.approx([2.07, 0.69, -0.62, -0.27], abs=0.05)
    clearance, cos = _nearest_skin(points, clearance, cos, skin, axis)
    assert -clearance * cos == pytest.approx(exact, abs=0.05)


def test_a_rim_point_in_the_crease_under_the_wing_is_no_deeper_than_its_distance_from_the_skin():
    """Skin: a flat floor rising steeply (1.5 mm per mm) into the underside of the wing of the nose,
    seen by the camera up to x = 1 mm (a hole beyond), and the wing's front 10 mm up, seen from in
    front. Rim points 0.25-6 mm under the floor along the axis, some past the hole's edge: along the
    axis the first surface up is the wing's front, so past the edge they read 7-11.5 mm deep; each
    reads inside the skin by its distance from the scanned skin (0.05 mm)."""
    from tests.test_cushion import grid_faces

    def floor(x):
        return np.where(x < 0, 0.0, 1.5 * x)

    n, m = 121, 41
    xy = np.stack(np.meshgrid(np.linspace(-15, 15, n), np.linspace(-15, 15, n)), -1).reshape(-1, 2)
    seen = trimesh.Trimesh(np.column_stack([xy, floor(xy[:, 0])]), grid_faces(n), process=False)
    seen = trimesh.Trimesh(seen.vertices, seen.faces[seen.triangles_center[:, 0] < 1.0], process=False)
    seen.remove_unreferenced_vertices()
    front = np.stack(np.meshgrid(np.linspace(-4, 10, m), np.linspace(-10, 10, m)), -1).reshape(-1, 2)
    skin = trimesh.util.concatenate([seen, trimesh.Trimesh(np.column_stack([front, np.full(len(front), 10.0)]), grid_faces(m), process=False)])
    points = np.array([[x, 0.3, z] for x in np.arange(-1.0, 3.01, 0.25) for z in np.arange(-1.5, 3.01, 0.25) if z < floor(x) - 0.2])
    axis = np.array([0.0, 0.0, 1.0])
    along, under = _skin_below(points, skin, axis)
    clearance, cos = _nearest_skin(points, along, np.abs(_skin_planes(under, skin)[0] @ axis), skin, axis)
    assert (along[points[:, 0] > 1.0] < -7.0).sum() >= 8
    assert (clearance < 0).all()
    assert -clearance * cos == pytest.approx(trimesh.proximity.closest_point(skin, points)[1], abs=0.05)


def test_a_rim_point_under_a_triangle_spanning_the_crease_is_pressed_by_its_distance_from_it():
    """A capture's skin, 1.2 mm apart: a floor up to the crease under the wing of the nose, long
    triangles spanning the crease up to the wing's lip 3 mm across and 6 mm up, a hole beside them
    (skin the camera missed) and the wing's front 10 mm up. Rim points 2 mm under the spanning
    triangles, beside the hole: along the axis the first surface up is the wing's front (9 mm);
    their nearest skin lies on a spanning triangle, 1.1 mm over the mean of the floor's vertices
    near it (the skin bending away round it, not a spike standing out of it), so each is pressed
    by its distance from that skin (0.9-1.2 mm)."""
    from tests.test_cushion import grid_faces

    n = 12
    x, y = np.meshgrid(np.append(np.arange(-12.0, 0.1, 1.2), 3.0), np.arange(-7.2, 6.1, 1.2))
    skin = trimesh.Trimesh(np.column_stack([x.ravel(), y.ravel(), np.where(x.ravel() > 0, 6.0, 0.0)]), grid_faces(n), process=False)
    centre = skin.triangles_center
    skin = trimesh.Trimesh(skin.vertices, skin.faces[~((centre[:, 0] > 0) & (centre[:, 1] > 0))], process=False)
    front = np.stack(np.meshgrid(np.linspace(-4, 12, 41), np.linspace(-12, 12, 41)), -1).reshape(-1, 2)
    skin = trimesh.util.concatenate([skin, trimesh.Trimesh(np.column_stack([front, np.full(len(front), 10.0)]), grid_faces(41), process=False)])
    points = np.array([[1.5, 0.3, 1.0], [1.5, 0.8, 1.0], [1.0, 0.8, 0.6]])
    axis = np.array([0.0, 0.0, 1.0])
    along, under = _skin_below(points, skin, axis)
    clearance, cos = _nearest_skin(points, along, np.abs(_skin_planes(under, skin)[0] @ axis), skin, axis)
    assert along == pytest.approx(points[:, 2] - 10.0, abs=1e-6)
    assert -clearance * cos == pytest.approx(trimesh.proximity.closest_point(skin, points)[1], abs=0.02)


def test_a_rim_point_over_a_flap_curled_under_the_skin_is_pressed_by_its_depth_under_the_skin():
    """A flat skin (0.5 mm grid) and, 1.5 mm under it, a 1 mm flap of a torn edge curled under
    the surface. A rim point 1.2 mm under the skin, 0.3 mm over the flap: its nearest skin, the
    flap, lies 1.2 mm under the mean of the skin around it, so the point is pressed by its depth
    along the axis (1.2 mm), not by its distance to the flap."""
    from tests.test_cushion import grid_faces

    n, m = 61, 3
    xy = np.stack(np.meshgrid(np.linspace(-15, 15, n), np.linspace(-15, 15, n)), -1).reshape(-1, 2)
    flap = np.stack(np.meshgrid(np.linspace(-0.5, 0.5, m), np.linspace(-0.5, 0.5, m)), -1).reshape(-1, 2)
    skin = trimesh.util.concatenate([trimesh.Trimesh(np.column_stack([xy, np.zeros(len(xy))]), grid_faces(n), process=False),
                                     trimesh.Trimesh(np.column_stack([flap, np.full(len(flap), -1.5)]), grid_faces(m), process=False)])
    points = np.array([[0.1, 0.2, -1.2]])
    axis = np.array([0.0, 0.0, 1.0])
    along, under = _skin_below(points, skin, axis)
    clearance, cos = _nearest_skin(points, along, np.abs(_skin_planes(under, skin)[0] @ axis), skin, axis)
    assert -clearance * cos == pytest.approx([1.2], abs=0.01)


def test_a_rim_point_under_a_sheet_the_scan_sees_only_from_in_front_is_in_the_air():
    """Skin: a flat floor, and 12 mm above part of it a sheet scanned only from in front (the wing
    of the nose, its underside hidden from the camera, over the groove beside it); the floor has a
    hole under the sheet (skin the camera cannot see). Rim points 0.4-1.5 mm over the floor's
    plane under the sheet: along the axis the first surface up is the sheet, facing out, so they
    read 10.5-11.6 mm inside the skin; the nearest skin is the floor below them, or the hole's edge
    1 mm to the side, and they are in the air by their height over the floor's plane (not by their
    distance to the hole's edge, 1.4-1.8 mm)."""
    from tests.test_cushion import grid_faces

    n = 61
    xy = np.stack(np.meshgrid(np.linspace(-15, 15, n), np.linspace(-15, 15, n)), -1).reshape(-1, 2)
    floor = trimesh.Trimesh(np.column_stack([xy, np.zeros(len(xy))]), grid_faces(n), process=False)
    centre = floor.triangles_center
    hole = (np.abs(centre[:, 0] + 9.0) < 2.0) & (np.abs(centre[:, 1]) < 4.0)  # x -11..-7, y -4..4
    floor = trimesh.Trimesh(floor.vertices, floor.faces[~hole], process=False)
    floor.remove_unreferenced_vertices()
    sheet = trimesh.Trimesh(np.column_stack([0.5 * xy - [7.0, 0.0], np.full(len(xy), 12.0)]), grid_faces(n), process=False)
    skin = trimesh.util.concatenate([floor, sheet])
    points = np.array([[-5.0, 0.0, 0.4], [-8.0, 2.0, 1.0], [-10.0, -3.0, 1.5]])
    axis = np.array([0.0, 0.0, 1.0])
    clearance, under = _skin_below(points, skin, axis)
    assert clearance[0] == pytest.approx(0.4 - 12.0, abs=1e-6)
    clearance, cos = _nearest_skin(points, clearance, np.abs(_skin_planes(under, skin)[0] @ axis), skin, axis)
    assert clearance == pytest.approx(points[:, 2], abs=0.01) and cos == pytest.approx(1.0, abs=1e-6)


def test_a_rim_point_past_the_middle_of_a_sheet_scanned_on_both_sides_stays_inside():
    """Skin: a closed slab 4 mm thick (both of its sides in the scan, wound outwards). Rim points
    3.0 and 3.4 mm under its top, 1.0 and 0.6 mm over its underside: the nearest skin is the
    underside, facing away from the mask, so they are inside the slab, 3.0 and 3.4 mm deep along
    the axis, not in the air over the underside."""
    slab = trimesh.creation.box([30.0, 30.0, 4.0]).subdivide_to_size(1.0)
    points = np.array([[0.0, 0.0, -1.0], [3.0, 2.0, -1.4]])
    axis = np.array([0.0, 0.0, 1.0])
    clearance, under = _skin_below(points, slab, axis)
    clearance, _ = _nearest_skin(points, clearance, np.abs(_skin_planes(under, slab)[0] @ axis), slab, axis)
    assert clearance == pytest.approx([-3.0, -3.4], abs=0.01)


def test_a_rim_pressed_into_a_point_cloud_reads_its_depth_not_its_distance_to_a_sample():
    """A flat point cloud 1.3 mm apart: rim points 0.2-1 mm into it, up to 0.9 mm across from the
    nearest sample, read their depth under the plane of the points (not 0.5 mm deeper)."""
    grid = np.stack(np.meshgrid(np.arange(-20, 21, 1.3), np.arange(-20, 21, 1.3)), -1).reshape(-1, 2)
    cloud = trimesh.PointCloud(np.column_stack([grid, np.zeros(len(grid))]))
    points = np.array([[0.4, 0.5, -0.2], [-0.6, 0.3, -1.0], [0.65, 0.65, -0.5]])
    axis = np.array([0.0, 0.0, 1.0])
    clearance, under = _skin_below(points, cloud, axis)
    clearance, cos = _nearest_skin(points, clearance, np.abs(_skin_planes(under, cloud)[0] @ axis), cloud, axis)
    assert clearance * cos == pytest.approx([-0.2, -1.0, -0.5], abs=0.01)


def test_rim_over_a_sloping_point_cloud_measures_the_same_clearance_as_over_its_mesh():
    """A scan without triangles: the skin under the rim is a plane fitted to the points near the ray."""
    grid = np.stack(np.meshgrid(np.arange(-60, 61, 1.3), np.arange(-60, 61, 1.3)), -1).reshape(-1, 2)
    slope = np.column_stack([grid, 0.4 * grid[:, 0]])  # skin rising 0.4 mm per mm towards +x
    mesh = trimesh.Trimesh(slope, Delaunay(grid).simplices)
    ring = trimesh.creation.annulus(RING_MM, RING_MM + 6, 10).apply_translation((0, 0, 30))
    axis, up = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    over_mesh = find_rim(ring, mesh, mesh, axis, up)
    over_cloud = find_rim(ring, trimesh.PointCloud(slope), mesh, axis, up)
    assert over_cloud.covered.all()
    assert over_cloud.clearance == pytest.approx(over_mesh.clearance, abs=0.05)


@pytest.mark.parametrize("as_cloud", [False, True])
def test_the_skins_slope_under_the_rim_is_the_scans_not_the_registered_faces(as_cloud):
    """The rim's |cos| is the scan's own normal's, averaged under the flange: a scan sloping at 60
    degrees to the axis, noisy by 0.2 mm, reads cos 0.5 where the registered face over it ripples
    (1.5 mm high, 5 mm long: its own slope swings between 10 and 75 degrees to the axis)."""
    grid = np.stack(np.meshgrid(np.arange(-70, 71, 1.0), np.arange(-40, 41, 1.0)), -1).reshape(-1, 2)
    noise = np.random.default_rng(0).normal(0.0, 0.2, len(grid))
    skin = np.column_stack([grid, np.sqrt(3.0) * grid[:, 0] + noise])  # normal at 60 degrees to z
    scan = trimesh.PointCloud(skin) if as_cloud else trimesh.Trimesh(skin, Delaunay(grid).simplices)
    ripple = np.column_stack([grid, np.sqrt(3.0) * grid[:, 0] + 1.5 * np.sin(2 * np.pi * grid[:, 0] / 5.0)])
    face = trimesh.Trimesh(ripple, Delaunay(grid).simplices)
    ring = trimesh.creation.annulus(6.0, 10.0, 10).apply_translation((0, 0, 30))
    rim = find_rim(ring, scan, face, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    assert rim.covered.mean() > 0.9
    assert rim.cos[rim.covered] == pytest.approx(np.full(rim.covered.sum(), 0.5), abs=0.06)  # 60 +- 4 degrees


def test_the_rim_is_where_the_cushion_first_touches_the_scanned_skin_not_the_registered_face():
    """Skin rising 0.5 mm a mm outwards under a flat flange (radius 30-36 mm, 8 mm up) touches its
    outer edge first: the rim runs there (sealed area within 2 % of a 36 mm disc, clearance 6.5 mm)
    though the registered face under it falls outwards (it would pick the inner edge, 30 mm)."""
    grid = np.stack(np.meshgrid(np.arange(-60, 61, 1.0), np.arange(-60, 61, 1.0)), -1).reshape(-1, 2)
    r = np.linalg.norm(grid, axis=1)
    tri = Delaunay(grid).simplices
    scan = trimesh.Trimesh(np.column_stack([grid, 0.5 * (r - 33.0)]), tri)
    face = trimesh.Trimesh(np.column_stack([grid, -0.5 * (r - 33.0)]), tri)
    ring = trimesh.creation.annulus(30.0, 36.0, 2.0).apply_translation((0, 0, 9.0))  # bottom at z = 8
    rim = find_rim(ring, scan, face, np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    assert rim.covered.all()
    assert rim.sealed_area_mm2 == pytest.approx(np.pi * 36.0**2, rel=0.02)
    assert np.median(rim.clearance) == pytest.approx(6.5, abs=0.1)


def test_tissue_over_the_nasal_bones_is_stiffest():
    k = stiffness(np.array([6, 205, 152]))  # nasal bridge, cheek, chin
    assert k.region == ("nasal bridge", "cheek", "chin")
    assert k.tissue[0] > 5 * k.tissue[1] and k.tissue[1] < k.tissue[2] < k.tissue[0]
    assert (k.effective < k.tissue).all() and (k.effective < FitParams().tissue.cushion_kpa_per_mm).all()  # springs in series


def test_custom_cushion_seals_evenly_where_the_best_stock_size_does_not(designed):
    """At 10 cmH2O, the custom cushion at its recommended force and the best stock size at the
    force a clinic sets: the custom one presses evenly, the stock one (a shape that is no one's) not."""
    _, d = designed
    custom, stock = d.fits["custom"].summary(), d.fits["stock"].summary()
    assert custom["leak_l_min"] <= 1.0 and custom["window_fraction"] >= 0.95
    assert stock["pressure_cv"] >= 2 * custom["pressure_cv"]
    assert custom["seal_force_n"] <= d.fits["custom"].force_n  # seals at the force it is set to


def test_compensation_evens_out_the_rim_pressure(designed, placed_subjects):
    """At its recommended force the custom rim presses near the target everywhere it is in contact
    (the force it is set to may be more, for the sleep states, or less, for the awake peak)."""
    ph, d = designed
    face = face_for(placed_subjects(ph.seed)[1], d.alignment, d.registration)
    fit = fit_rim(d.fits["custom"].rim, face, d.cushion.params.flange_mm, None, d.fit_params)
    p = fit.pressure_kpa[fit.rim.covered]
    assert np.median(p) == pytest.approx(d.fit_params.target_kpa, abs=0.3)
    assert d.preload.mm.min() == 0.0 and d.preload.mm.max() > 0.5  # soft tissue gets more pre-load


@pytest.mark.parametrize("shares, kept", [((0.8, 1.0, 1.0), 1), ((0.8, 0.9, 0.85, 1.0), 1), ((0.8, 0.9, 0.95, 0.97, 0.99, 1.0), 4)])
def test_the_preload_is_corrected_while_each_correction_brings_more_of_the_rim_into_the_window(shares, kept, monkeypatch):
    """`corrected` corrects once, then again while the rim is not all in the window and the next
    correction brings more of it in, CORRECTIONS (4) times at most, and keeps the last that did, with
    its cushion: the pre-load here counts its corrections, `shares[n]` the window share after n, and
    its cushion is that count."""
    monkeypatch.setattr(compensation, "pressed", lambda preload, *given: (int(preload[0]), SimpleNamespace(window_fraction=shares[int(preload[0])])))
    monkeypatch.setattr(compensation, "refined_preload", lambda preload, *given: preload + 1.0)
    assert compensation.CORRECTIONS == 4
    preload, cushion = corrected(np.zeros(128), SimpleNamespace(curve=None), None, None, None, None, 3.0)
    assert preload[0] == kept and cushion == kept


def test_a_narrow_peak_left_by_one_correction_is_corrected_into_the_window(designed, placed_subjects, monkeypatch):
    """The design's pre-load set 5 mm deeper over 3 seal samples (of 128), within MAX_PRELOAD_MM,
    presses a narrow peak over capillary closing at the recommended force. One correction, clipped
    to STEP_MM and smoothed, leaves it there; `corrected` presses and corrects again until the whole
    rim lies in the window. A pre-load whose first correction fills the window is corrected once."""
    ph, d = designed
    face = face_for(placed_subjects(ph.seed)[1], d.alignment, d.registration)
    given = d.contact, face, d.registration.vertices, d.cushion.params, d.fit_params
    bump = np.where(np.abs(np.arange(len(d.preload.mm)) - 60) <= 1, 5.0, 0.0)
    bumped = np.minimum(d.preload.mm + bump, MAX_PRELOAD_MM)
    assert pressed(corrected(bumped, *given, d.preload.smoothing)[0], *given)[1].window_fraction == 1.0
    monkeypatch.setattr(compensation, "CORRECTIONS", 1)
    once = pressed(corrected(bumped, *given, d.preload.smoothing)[0], *given)[1]
    assert once.window_fraction < 0.99 and once.pressure_kpa[once.rim.covered].max() > d.fit_params.capillary_kpa
    again = corrected(d.preload.mm, *given, d.preload.smoothing)[0]
    monkeypatch.undo()
    assert pressed(again, *given)[1].window_fraction == 1.0
    assert np.array_equal(corrected(d.preload.mm, *given, d.preload.smoothing)[0], again)


def test_a_point_cloud_edge_in_a_row_does_not_tilt_the_skin_away():
    """Under a rim point beside a cloud's edge, the only points near the ray lie nearly in a row
    (the edge, 1.5 mm away): the plane through them may tilt at random across the row, but the
    skin's height is kept within theirs: 0.95-1.05 mm below the point (the plane's own: 1.27 mm)."""
    rng = np.random.default_rng(0)
    x = np.arange(-3.0, 3.01, 0.5)
    row = np.column_stack([x, rng.normal(0.0, 0.01, len(x)), rng.uniform(-0.05, 0.05, len(x))])
    clearance, _ = _skin_below(np.array([[0.0, 1.5, 1.0]]), trimesh.PointCloud(row), np.array([0.0, 0.0, 1.0]))
    assert 0.95 <= clearance[0] <= 1.05


def test_a_point_cloud_too_sparse_for_the_rim_is_refused_in_words():
    """A cloud of points 4 mm apart under a cushion: no ray has points within 2 mm, and the refusal
    says the cloud is too sparse, how far apart its points are, and what to export instead."""
    grid = np.stack(np.meshgrid(np.arange(-60, 61, 4.0), np.arange(-60, 61, 4.0)), -1).reshape(-1, 2)
    flat = np.column_stack([grid, np.zeros(len(grid))])
    ring = trimesh.creation.annulus(RING_MM, RING_MM + 6, 10).apply_translation((2.0, 2.0, 30))
    axis, up = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    with pytest.raises(InputError, match="4.0 mm apart, too sparse .* export a denser cloud, or a mesh"):
        find_rim(ring, trimesh.PointCloud(flat), trimesh.Trimesh(flat, Delaunay(grid).simplices), axis, up)


def test_a_membranes_pull_holds_a_mask_on_past_the_cpap_load_and_balances_what_the_skin_does_not_take():
    """Flaps pulling 2 N in all, evenly, on a flat rim (skin at cos 0.8) under 2.8 N of CPAP load,
    each closing openings up to 1 mm: held on from 1 mN past the least force, the CPAP load less the
    whole pull (without the flaps, or with flaps that close no opening, it lifts off), lifted 1 mN
    short of it; the wall pressed in under ROOT_MM (normal) where the pulls ease off, and the skin's
    push along the axis is the headgear's and the pulls' less the CPAP load (within 1e-6 N)."""
    cpap, area, cos = 1.0, np.pi * RING_MM**2, 0.8
    pull = np.full(K, 2.0 / K)
    flaps = Flaps(pull, np.full(K, 1.0))
    args = (np.zeros(K), np.full(K, cos), np.full(K, AREA), np.full(K, 1.0), ring_uv(), area)
    least = least_force_n(*args[1:3], ring_uv(), area, cpap, pull)
    assert least == pytest.approx(cpap * area * 1e-3 - 2.0, abs=1e-9)
    held = press(*args, least + 1e-3, cpap, flaps)
    assert not held.lifted and press(*args, least - 1e-3, cpap, flaps).lifted
    assert press(*args, least + 1e-3, cpap).lifted and press(*args, least + 1e-3, cpap, Flaps(pull, np.zeros(K))).lifted
    indent = held.pressure_kpa / 1.0  # mm normal to the skin, k = 1 kPa/mm
    assert 0 < indent.max() < ROOT_MM
    skin = held.pressure_kpa @ np.full(K, AREA * cos) * 1e-3
    assert skin == pytest.approx(least + 1e-3 - cpap * area * 1e-3 + pull @ (1 - indent / ROOT_MM), abs=1e-6)


def test_pulls_on_one_side_hold_the_mask_on_only_as_far_as_it_cannot_tip_off_over_the_other():
    """The same 2 N of pull only where u > 15 mm (a sixth of the rim): the mask would tip off about
    the rim's edge beside the pulls, its other side lifting, before it slid off, so the least force is
    the CPAP load less the pulls' moment about that edge over the load's (about 0.34 N held, not 2;
    within 2 %: the edge is a chord of the 256 points): 1 mN short of it the mask lifts off; 0.3 N
    past it it stays on, tilted under 0.05 (the far side lifted, every opening within the flaps'
    2 mm reach)."""
    cpap, area, uv = 1.0, np.pi * RING_MM**2, ring_uv()
    side = uv[:, 0] > 15.0
    pull = np.where(side, 2.0 / side.sum(), 0.0)
    flaps = Flaps(pull, np.full(K, 2.0))
    args = (np.zeros(K), np.ones(K), np.full(K, AREA), np.full(K, 1.0), uv, area)
    least = least_force_n(*args[1:3], uv, area, cpap, pull)
    tip = pull @ (RING_MM - uv[:, 0]) / RING_MM  # about the edge at u = 30 mm, the load's line at the centre
    assert cpap * area * 1e-3 - least == pytest.approx(tip, rel=0.02)
    assert press(*args, least - 1e-3, cpap, flaps).lifted
    held = press(*args, least + 0.3, cpap, flaps)
    assert not held.lifted and 0 < held.tilt[0] < 0.05 and held.opening_mm.max() <= 2.0


def test_a_scan_denser_than_half_a_millimetre_is_pressed_on_thinned_with_the_same_fit(nasal1, phantom1):
    """Seed 1's true face near its seal as a mesh of ~1 mm edges, and the same surface subdivided to
    0.3 mm edges: the dense one is pressed on thinned (median edge 0.4-0.7 mm), and seed 1's custom
    cushion pressed on each at its force gives the same rim (clearance within 0.05 mm at the median
    sector, 0.2 mm at the 95th percentile), peak within 0.1 kPa, window within 2 % and no leak."""
    from cpapfit.clustering import median_edge
    from cpapfit.pipeline import face_for
    from cpapfit.scan import Scan

    d = nasal1.design
    near = np.linalg.norm(phantom1.surface - d.fits["custom"].rim.points.mean(axis=0), axis=1) < 45.0
    faces = phantom1.faces[near[phantom1.faces].all(axis=1)]
    coarse = trimesh.Trimesh(phantom1.surface, faces)
    coarse.remove_unreferenced_vertices()
    dense = trimesh.Trimesh(*trimesh.remesh.subdivide_to_size(coarse.vertices, coarse.faces, 0.3))
    assert median_edge(dense.vertices, dense.faces) < 0.3
    fits = []
    for mesh in (coarse, dense):
        face = face_for(Scan(np.asarray(mesh.vertices), np.asarray(mesh.faces), np.asarray(mesh.vertex_normals)), d.alignment, d.registration)
        fits.append(fit_cushion(d.solid, face, d.cushion.params.flange_mm, d.fits["custom"].force_n, d.fit_params))
    assert 0.4 <= median_edge(np.asarray(face.scan.vertices), np.asarray(face.scan.faces)) <= 0.7
    gap = np.abs(fits[0].rim.clearance - fits[1].rim.clearance)
    assert np.nanmedian(gap) <= 0.05 and np.nanpercentile(gap, 95) <= 0.2
    (a, b) = (f.summary() for f in fits)
    assert b["pressure_max_kpa"] == pytest.approx(a["pressure_max_kpa"], abs=0.1)
    assert b["window_fraction"] == pytest.approx(a["window_fraction"], abs=0.02)
    assert a["leak_l_min"] == b["leak_l_min"] == 0.0


def test_no_ray_along_the_axis_meets_a_surface_above_its_ceiling():
    """`ceilings`: from 4000 points over and under a bumpy sheet of long and short triangles, the
    first surface up and down the axis lies no higher up it than the point's ceiling, and points
    beside the sheet, which no ray from them can meet, have none."""
    rng = np.random.default_rng(5)
    xy = np.vstack([rng.uniform(-20.0, 20.0, (300, 2)), [[-20, -20], [-20, 20], [20, -20], [20, 20]]])
    turn = trimesh.transformations.random_rotation_matrix(rng.random(3))[:3, :3]  # the axis and the plane tilted
    sheet = trimesh.Trimesh(np.column_stack([xy, 3.0 * np.sin(xy[:, 0] / 4.0) * np.cos(xy[:, 1] / 5.0)]) @ turn.T,
                            Delaunay(xy).simplices, process=False)
    axis, plane = turn[:, 2], turn[:, :2].T
    local = np.column_stack([rng.uniform(-25.0, 25.0, (4000, 2)), rng.uniform(-6.0, 6.0, 4000)])
    points = local @ turn.T
    ceiling = ceilings(points @ plane.T, [sheet], axis, plane)
    for direction in (axis, -axis):
        where, ray, _ = sheet.ray.intersects_location(points, np.broadcast_to(direction, points.shape), multiple_hits=False)
        assert len(ray) > 1000
        assert np.all(where @ axis <= ceiling[ray])
    beside = np.any(np.abs(local[:, :2]) > 21.0, axis=1)
    assert beside.sum() > 500 and np.all(ceiling[beside] == -np.inf)


def test_a_wall_whose_lowest_ring_faces_a_closed_slab_from_below_reads_the_slab_from_the_whole_band(monkeypatch):
    """Which side of a scan is out is voted on by hits from the whole wall band, not only its lowest
    millimetre: rings of wall 28-30 mm round the axis, the lowest (z -3.1) under a closed 3 mm slab
    (the scan, its top at z 0) and seeing only its underside, one inside it (z -0.5), more above:
    the rim is the ring inside the slab, 0.5 mm deep, as casting from every vertex finds it."""
    turn = np.linspace(0.0, 2 * np.pi, 1024, endpoint=False)
    ring = lambda radius, z: np.column_stack([radius * np.cos(turn), radius * np.sin(turn), np.full(len(turn), z)])
    wall = np.vstack([ring(30.0, -3.1), ring(28.0, -0.5), *(ring(30.0, z) for z in np.arange(0.5, 10.0, 0.5))])
    zone = RimZone(wall, np.zeros((0, 3)), np.zeros(0), np.zeros(3))
    slab = trimesh.creation.box(extents=[140.0, 140.0, 3.0])
    slab.apply_translation([0.0, 0.0, -1.5])
    elsewhere = trimesh.creation.box(extents=[10.0, 10.0, 1.0])
    elsewhere.apply_translation([500.0, 0.0, 0.0])
    axis, up = np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0])
    spared = rim_in(zone, slab, elsewhere, axis, up)
    assert np.allclose(spared.points[:, 2], -0.5) and np.allclose(spared.clearance, -0.5, atol=1e-6)
    monkeypatch.setattr(rim, "SURE_MM", rim.RIM_BAND_MM)
    every = rim_in(zone, slab, elsewhere, axis, up)
    assert np.array_equal(spared.points, every.points) and np.array_equal(spared.clearance, every.clearance)
