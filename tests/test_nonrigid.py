"""Non-rigid registration on synthetic subjects: fit, correspondence, holes, both lookup modes."""

from dataclasses import replace

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from cpapfit.align.laplacian import laplacian
from cpapfit.align.nonrigid import NonrigidParams, register, vertex_normals
from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.write import write_files
from cpapfit.landmarks.types import Landmarks
from cpapfit.synthetic.accuracy import flipped_triangles, scan_to_template
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.synthetic.camera import FRAMED
from cpapfit.pipeline import align, register_template
from cpapfit.rgbd import project
from cpapfit.scan import Scan
from cpapfit.template import load_template, mask_region

TEMPLATE = load_template()
REGION = mask_region(TEMPLATE)


def registered(scan: Scan, alignment=None):
    """The template registered on a scan from its own alignment (landmarks, similarity; `align(scan)`
    if None), without a shape basis: the affine start's run alone."""
    alignment = align(scan) if alignment is None else alignment
    return register(alignment.similarity.apply(TEMPLATE.vertices), TEMPLATE.faces, scan, alignment.landmarks, mirror=TEMPLATE.mirror)


def write_capture(ph, folder, depth=None):
    write_files(folder, capture_files(ph.image, ph.depth_raw if depth is None else depth, ph.intrinsics, ph.sensor.depth_scale))
    return load_scan(folder)


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """Seed 1: the scan, its truth, and registrations in both correspondence modes."""
    ph = make_phantom(1)
    scan = write_capture(ph, tmp_path_factory.mktemp("reg"))
    al = align(scan)
    aligned = al.similarity.apply(TEMPLATE.vertices)
    regs = {mode: register(aligned, TEMPLATE.faces, scan, al.landmarks, NonrigidParams(correspondence=mode), TEMPLATE.mirror)
            for mode in ("grid", "kdtree")}
    return ph, scan, aligned, regs


def test_registered_template_lies_on_the_scan(case):
    _, scan, _, regs = case
    d = scan_to_template(scan.vertices, regs["grid"].vertices, TEMPLATE.faces, REGION)
    assert len(d) > 3000
    assert np.median(d) <= 0.3 and np.percentile(d, 95) <= 1.0


def test_registration_improves_correspondence(case):
    """Each mask-region vertex ends within 1 mm (mean) of its true position, far nearer than after
    the similarity alone (this seed: 2.5 mm)."""
    ph, _, aligned, regs = case
    before = np.linalg.norm(aligned[REGION] - ph.surface[REGION], axis=1).mean()
    after = np.linalg.norm(regs["grid"].vertices[REGION] - ph.surface[REGION], axis=1).mean()
    assert after <= 1.0 and after < 0.5 * before


def test_no_flipped_triangles_in_the_mask_region(case):
    _, _, aligned, regs = case
    assert flipped_triangles(aligned, regs["grid"].vertices, TEMPLATE.faces, REGION) == 0


def test_grid_and_kdtree_correspondences_agree(case):
    _, _, _, regs = case
    gap = np.linalg.norm(regs["grid"].vertices[REGION] - regs["kdtree"].vertices[REGION], axis=1)
    assert gap.mean() <= 0.2


def test_detected_landmarks_pull_with_a_tenth_of_the_paper_weight(case):
    log = case[3]["grid"].log
    assert log[0].membrane == 100.0 and log[0].landmark == pytest.approx(1.0)


def test_paper_mode_follows_the_paper_schedule(case):
    """Without the affine start and with full landmark weight: the paper's weights, halved."""
    _, scan, aligned, _ = case
    al = align(scan)
    log = register(aligned, TEMPLATE.faces, scan, al.landmarks, NonrigidParams(affine=None, detected_landmark_factor=1.0, coarse_gates=None)).log
    assert log[0].membrane == 100.0 and log[0].landmark == 10.0
    halved = [b for a, b in zip(log, log[1:]) if b.membrane < a.membrane]
    assert all(b.membrane == pytest.approx(a.membrane / 2) for a, b in zip(log, log[1:]) if b.membrane < a.membrane)
    assert len(halved) >= 3 and log[-1].mean_residual_mm < log[0].mean_residual_mm


def user_landmarks(scan, points, index, sigma):
    """A user's landmarks file: `points` moved sigma mm (per axis, seed 0) and put back on the skin."""
    moved = points + np.random.default_rng(0).normal(0.0, sigma, points.shape)
    return Landmarks(scan.vertices[cKDTree(scan.vertices).query(moved)[1]], index, np.ones(len(index)), "user")


def test_a_users_landmarks_earn_the_paper_weight_only_if_they_agree_with_the_face(case):
    """Placed to ~1 mm (the truth moved 1 mm): the paper's weight, and the mask region at least as
    near its true place as with detected landmarks; 4 mm off along the skin: a tenth of it, and the
    mask region within 0.2 mm of where detected landmarks put it (at the paper's weight those
    landmarks drag it 0.05 mm or more further off: 0.09 with the mirror term, 0.1 without)."""
    ph, scan, aligned, regs = case
    index = align(scan).landmarks.template_index
    error = lambda reg: np.linalg.norm(reg.vertices[REGION] - ph.surface[REGION], axis=1).mean()  # noqa: E731
    good = register(aligned, TEMPLATE.faces, scan, user_landmarks(scan, ph.surface[index], index, 1.0), mirror=TEMPLATE.mirror)
    assert good.landmark_factor == 1.0 and good.landmark_spread_mm <= 2.0
    assert error(good) <= error(regs["grid"]) + 0.05
    careless = user_landmarks(scan, ph.surface[index], index, 4.0)
    bad = register(aligned, TEMPLATE.faces, scan, careless, mirror=TEMPLATE.mirror)
    assert bad.landmark_factor == pytest.approx(0.1) and bad.landmark_spread_mm >= 3.0
    assert error(bad) <= error(regs["grid"]) + 0.2
    trusted = register(aligned, TEMPLATE.faces, scan, careless, NonrigidParams(user_trust_mm=np.inf), TEMPLATE.mirror)
    assert error(trusted) >= error(bad) + 0.05


def test_the_mirror_term_keeps_a_turned_face_from_sliding(tmp_path):
    """Subject 127 turned 20 deg, the nose hiding part of the far side: without the mirror term its mask
    region ends 1.10 mm (mean) from the truth, slid sideways along the skin, the hidden part left where
    the affine start put it; held symmetric about the scan's own plane of symmetry, 0.84 mm."""
    ph = make_phantom(127, yaw_deg=20.0, pose=FRAMED)
    scan = write_capture(ph, tmp_path)
    al = align(scan)
    aligned = al.similarity.apply(TEMPLATE.vertices)
    error = {}
    for mirror in (None, TEMPLATE.mirror):
        reg = register(aligned, TEMPLATE.faces, scan, al.landmarks, mirror=mirror)
        error[mirror is None] = np.linalg.norm(reg.vertices[REGION] - ph.surface[REGION], axis=1).mean()
    assert error[False] <= 0.95 and error[False] <= error[True] - 0.15


def test_holes_are_bridged(tmp_path):
    """30 % of the mask region's depth removed in blobs: the membrane carries the template across."""
    ph = make_phantom(2)
    rng = np.random.default_rng(0)
    uv = np.round(project(ph.surface[REGION], ph.intrinsics)).astype(int)
    on = np.zeros(ph.depth_raw.shape, bool)
    on[uv[:, 1], uv[:, 0]] = True
    region_px = on & (ph.depth_raw > 0)
    vv, uu = np.mgrid[: on.shape[0], : on.shape[1]]
    holes = np.zeros_like(on)
    while (holes & region_px).sum() < 0.3 * region_px.sum():
        c = uv[rng.integers(len(uv))]
        holes |= (uu - c[0]) ** 2 + (vv - c[1]) ** 2 <= rng.uniform(4, 9) ** 2
    scan = write_capture(ph, tmp_path, np.where(holes, 0, ph.depth_raw).astype(np.uint16))
    reg = registered(scan)
    in_hole = REGION[holes[uv[:, 1], uv[:, 0]]]
    err = np.linalg.norm(reg.vertices[in_hole] - ph.surface[in_hole], axis=1)
    assert len(in_hole) > 500
    assert err.mean() <= 2.0


def test_membrane_ignores_rigid_translation_and_is_positive():
    lap = laplacian(TEMPLATE.vertices, TEMPLATE.faces)
    assert abs(lap - lap.T).max() < 1e-12
    shift = np.ones(len(TEMPLATE.vertices))
    assert np.abs(lap @ shift).max() < 1e-9
    d = np.random.default_rng(0).normal(size=len(TEMPLATE.vertices))
    assert d @ (lap @ d) > 0


def test_vertex_normals_point_out_of_the_face():
    n = vertex_normals(TEMPLATE.vertices, TEMPLATE.faces)
    assert n[4] @ [0, 0, 1] > 0.9  # nose tip looks forward (+z in the template frame)


def read_ply_attributes(path):
    mesh = trimesh.load(path, process=False)
    data = mesh.metadata["_ply_raw"]["vertex"]["data"]
    return mesh, data["residual_mm"], data["valid"]


def test_register_command_writes_the_warped_template(cli, phantom1_dir, tmp_path):
    code, _, err = cli("register", phantom1_dir, "--out", tmp_path / "reg.ply", "--verbose")
    assert code == 0, err
    times = {line.split(":")[0].strip(): float(line.split(":")[1].split()[0]) for line in err.splitlines() if line.endswith(" s")}
    assert times.keys() >= {"landmarks and similarity", "non-rigid registration"} and all(t > 0 for t in times.values()), err
    mesh, residual, valid = read_ply_attributes(tmp_path / "reg.ply")
    assert len(mesh.vertices) == len(TEMPLATE.vertices) and np.array_equal(mesh.faces, TEMPLATE.faces)
    assert valid.mean() > 0.5 and np.median(residual[valid == 1]) < 0.3
    assert (residual[valid == 0] == -1).all()


@pytest.mark.shared
@pytest.mark.parametrize("name", ["fran_cyberware/fran.obj", "rgbd_truedepth_mannequin"])
def test_shared_real_scans_register(shared_data, name, cli, tmp_path):
    code, _, err = cli("register", shared_data / name, "--out", tmp_path / "reg.ply")
    assert code == 0, err
    mesh, residual, valid = read_ply_attributes(tmp_path / "reg.ply")
    assert np.median(residual[valid == 1]) < 0.5  # mm
    assert 100 < np.ptp(mesh.vertices, axis=0).max() < 250  # fran in metres comes out in mm


@pytest.mark.shared
def test_fran_registers_alike_under_a_ten_thousandth_of_a_millimetre(shared_data):
    """fran's vertices moved by 1e-4 mm noise (as another exporter's rounding would) register within
    0.1 mm on average, 0.5 mm at most, of fran's own over the mask region (0.02-0.04 / 0.13-0.21 mm
    over noise seeds 1-6): the registration is the morphable start's run (its share 1). The noise
    moves the detected landmarks (renders shade a little differently), and the affine start's run
    alone, whose ICP has not settled on fran, follows them by up to 1.2 mm (mean, seeds 1-4); begun
    at the similarity only, it lands 2.5 mm away (7 mm at most)."""
    def both(s: Scan):
        alignment = align(s)
        return register_template(s, alignment).vertices[REGION], registered(s, alignment).vertices[REGION]

    scan = load_scan(shared_data / "fran_cyberware" / "fran.obj")
    reference, affine = both(scan)
    for seed in (1, 4):
        noisy = replace(scan, vertices=scan.vertices + np.random.default_rng(seed).normal(0.0, 1e-4, scan.vertices.shape))
        design, alone = both(noisy)
        gap = np.linalg.norm(design - reference, axis=1)
        assert gap.mean() <= 0.1 and gap.max() <= 0.5
        assert np.linalg.norm(alone - affine, axis=1).mean() <= 1.5


def test_a_chin_far_from_the_template_is_pulled_in():
    """The template's own surface with everything below the lower lip pushed 12 mm forward over a
    10 mm ramp (the chin far and tilted, as fran's is): the paper's 5 mm / 25 deg gates leave it
    out (~7 mm off); the coarse gates bring it onto the scan."""
    v = TEMPLATE.vertices.copy()
    lip = v[14, 1]  # Face Mesh 14: the lower lip
    t = np.clip((lip - v[:, 1]) / 10.0, 0.0, 1.0)
    v[:, 2] += 12.0 * t * t * (3 - 2 * t)
    mesh = trimesh.Trimesh(v, TEMPLATE.faces, process=False)
    scan = Scan(v, TEMPLATE.faces, mesh.vertex_normals.copy())
    below = REGION[TEMPLATE.vertices[REGION, 1] < lip]
    off = {}
    for gates in (None, NonrigidParams().coarse_gates):
        reg = register(TEMPLATE.vertices, TEMPLATE.faces, scan, None, NonrigidParams(coarse_gates=gates))
        off[gates] = trimesh.proximity.closest_point(mesh, reg.vertices[below])[1]
    assert off[None].mean() > 3.0  # what the paper's gates do here
    assert off[NonrigidParams().coarse_gates].mean() <= 0.5 and np.percentile(off[NonrigidParams().coarse_gates], 95) <= 1.0
