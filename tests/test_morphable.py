"""The morphable start: the template's shape fitted within the ICT model's identity modes, and the
elastic ICP's two runs weighed: the morphable one kept where the face is clearly more like the
model's faces than the template's, the affine one where it is not, the two blended between."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from cpapfit.align.correspondences import make_target, oriented
from cpapfit.align.morphable import fit_shape
from cpapfit.align import nonrigid
from cpapfit.align.nonrigid import SHARE_DECIMALS, NonrigidParams, morphable_share, vertex_normals
from cpapfit.similarity import fit_similarity
from cpapfit.ict import ict_face, load_ict, template_truth
from cpapfit.synthetic.ict_phantom import make_ict_phantom
from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.write import write_files
from cpapfit.landmarks.types import Landmarks
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.synthetic.camera import FRAMED
from cpapfit.pipeline import align, register_template, template_basis
from cpapfit.scan import Scan
from cpapfit.template import load_template, mask_region

TEMPLATE = load_template()
REGION = mask_region(TEMPLATE)
BASIS = template_basis(40)
BLEND = NonrigidParams().morphable.blend


def _error(vertices: np.ndarray, truth: np.ndarray) -> float:
    """Mean distance (mm) of both masks' contact bands from their true places."""
    return float(np.linalg.norm(vertices[REGION] - truth[REGION], axis=1).mean())


def _capture(ph, folder) -> Scan:
    write_files(folder, capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
    return load_scan(folder)


def test_the_shape_fit_finds_a_model_face_and_its_pose():
    """A face of the model (its first 40 modes), as an exact mesh turned 10 deg and moved 4 mm from
    where the similarity puts the template: the fit lands every contact-band vertex on its true place."""
    rng = np.random.default_rng(5)
    face = template_truth(ict_face(load_ict(), rng.normal(size=40), {}))
    turn = Rotation.from_rotvec(np.radians(10.0) * np.array([0.6, 0.8, 0.0])).as_matrix()
    truth = face @ turn.T + [4.0, -2.0, 1.0]
    scan = Scan(truth, TEMPLATE.faces, vertex_normals(truth, TEMPLATE.faces))
    aligned = fit_similarity(TEMPLATE.landmarks[[33, 263, 61, 291, 4]], face[[33, 263, 61, 291, 4]]).apply(TEMPLATE.vertices)
    target = oriented(make_target(scan, False, 1.0), aligned, vertex_normals(aligned, TEMPLATE.faces))
    fitted = fit_shape(aligned, BASIS, target, lambda v: vertex_normals(v, TEMPLATE.faces), (0.1, 1.0), (15.0, 60.0))
    assert _error(aligned, truth) > 3.0
    assert _error(fitted, truth) < 0.3


@pytest.fixture(scope="module")
def ict_capture(tmp_path_factory):
    ph = make_ict_phantom(2, pose=FRAMED)
    return _capture(ph, tmp_path_factory.mktemp("ict2")), ph.surface


def test_an_ict_face_registers_from_the_morphable_start(ict_capture):
    """An ICT subject's capture (a face not made from the template): from the affine start alone the
    contact bands land 1.6 mm from their true places, the template sliding along the skin; the
    morphable start's run bends less and lies closer to the scan, is kept whole, and lands them within 0.8 mm."""
    scan, truth = ict_capture
    al = align(scan)
    without = register_template(scan, al, NonrigidParams(morphable=None))
    reg = register_template(scan, al)
    assert _error(without.vertices, truth) > 1.3
    assert _error(reg.vertices, truth) < 0.8
    assert reg.start == "morphable" and reg.bending < without.bending
    assert np.nanmean(reg.residual[reg.valid]) < np.nanmean(without.residual[without.valid])
    assert np.array_equal(reg.other_run, without.vertices) and reg.morphable_share == 1.0  # the run not kept, as fit.json reports it


@pytest.mark.shared
def test_a_run_that_bends_a_little_less_and_lies_closer_is_kept(shared_data, tmp_path):
    """ICT subject 9001 (all 100 modes) as a framed capture: the morphable start's run bends a little
    less than the affine start's (11 %), and also lies closer to the scan (product 0.82): it is kept
    whole, and lands the nasal contact band within 1.0 mm of its true place, where the affine start's
    run slid 2.6 mm along the skin, a design on the wrong place and nothing flagged."""
    ph = make_ict_phantom(9001, pose=FRAMED, model=load_ict(shared_data / "ict_face_model" / "ict_face_model.npz"))
    scan = _capture(ph, tmp_path)
    al = align(scan)
    reg = register_template(scan, al)
    affine = register_template(scan, al, NonrigidParams(morphable=None))
    band = TEMPLATE.regions["nasal"].band
    low = NonrigidParams().morphable.blend[0]
    assert reg.start == "morphable" and reg.morphable_share == 1.0 and reg.start_product < low
    assert low * affine.bending < reg.bending < affine.bending  # bending alone would not have told them apart
    assert np.linalg.norm(reg.vertices[band] - ph.surface[band], axis=1).mean() < 1.0
    assert np.linalg.norm(affine.vertices[band] - ph.surface[band], axis=1).mean() > 2.0


def test_a_template_subject_weighs_the_affine_start(tmp_path):
    """A subject made from the template: the model's shape explains it no better than the template's
    own (product 1.0-1.1), so the registration is the affine start's run with at most a fifth of the
    morphable start's blended in, vertex for vertex, the morphable run within 3 mm of it (mean); its
    pairs with the scan are measured on the blend (median under 0.15 mm), not the affine run's."""
    scan = _capture(make_phantom(4, pose=FRAMED), tmp_path / "capture")
    al = align(scan)
    reg = register_template(scan, al)
    affine_reg = register_template(scan, al, replace(NonrigidParams(), morphable=None))
    affine = affine_reg.vertices
    share = morphable_share(reg.start_product, BLEND)
    assert reg.start == "affine" and 1.0 <= reg.start_product <= 1.1 and 0.0 < share <= 0.2
    assert reg.morphable_share == pytest.approx(share, abs=10.0**-SHARE_DECIMALS)
    blend = reg.morphable_share * reg.other_run + (1.0 - reg.morphable_share) * affine
    assert np.allclose(reg.vertices, blend, rtol=0.0, atol=5e-4 + 1e-9)  # to the micrometre
    assert 0.0 < np.linalg.norm(reg.other_run - affine, axis=1).mean() < 3.0
    assert not np.array_equal(reg.valid, affine_reg.valid) or not np.allclose(reg.residual, affine_reg.residual, equal_nan=True)
    assert np.median(reg.residual[reg.valid]) < 0.15  # the blend matched to the scan again, and on it


def test_the_morphable_share_eases_between_the_blend_bounds():
    """The share is whole under the blend's low bound and none over its high one, half between them,
    falls monotonically and without a step (a product 0.01 further moves it at most 0.06), and is
    none where neither run paired (a product not a number)."""
    blend = (0.85, 1.1)
    products = np.linspace(0.5, 1.5, 1001)
    share = np.array([morphable_share(p, blend) for p in products])
    assert share[products <= 0.85].min() == 1.0 and share[products >= 1.1].max() == 0.0
    assert morphable_share(0.975, blend) == pytest.approx(0.5)
    assert np.all(np.diff(share) <= 0.0) and np.abs(np.diff(share)).max() <= 0.0061
    assert morphable_share(np.nan, blend) == 0.0 and morphable_share(np.inf, blend) == 0.0
    assert morphable_share(0.899, (0.9, 0.9)) == 1.0 and morphable_share(0.9, (0.9, 0.9)) == 0.0  # bounds met: a cut


def test_trusted_landmarks_register_both_runs_again_and_blend_them(tmp_path, monkeypatch):
    """A user's landmarks on the template subject's true places: trusted, both runs are registered
    again at the paper's weight and blended by the share of the product read at the first pass (at
    a tenth of the weight, as untrusted landmarks are): the registration is that blend of the affine
    run so registered (one start alone) and of the morphable run beside it, which is not the first
    pass's morphable run."""
    ph = make_phantom(4, pose=FRAMED)
    scan, truth = _capture(ph, tmp_path / "capture"), ph.surface
    al = align(scan)
    index = al.landmarks.template_index
    user = replace(al, landmarks=Landmarks(scan.vertices[cKDTree(scan.vertices).query(truth[index])[1]], index, np.ones(len(index)), "user"))
    weighed, weigh = [], nonrigid._weighed
    monkeypatch.setattr(nonrigid, "_weighed", lambda *args: weighed.append(weigh(*args)) or weighed[-1])
    trusted = register_template(scan, user)
    (untrusted, again) = weighed  # the first pass, and the runs registered again
    assert again.landmark_factor == 1.0
    affine = register_template(scan, user, replace(NonrigidParams(), morphable=None))
    share = trusted.morphable_share
    assert trusted.landmark_factor == affine.landmark_factor == 1.0 and untrusted.landmark_factor == pytest.approx(0.1)
    assert trusted.start_product == untrusted.start_product and 0.0 < share < 0.5
    assert share == pytest.approx(morphable_share(trusted.start_product, BLEND), abs=10.0**-SHARE_DECIMALS)
    assert np.allclose(trusted.vertices, share * trusted.other_run + (1.0 - share) * affine.vertices, rtol=0.0, atol=5e-4 + 1e-9)
    assert np.linalg.norm(trusted.other_run - untrusted.other_run, axis=1).mean() > 0.01
