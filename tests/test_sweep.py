"""Sweeps: a folder of capture folders fused into one scan, against a synthetic sweep's truth, and bad sweeps."""

import shutil
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from cpapfit.align.nonrigid import NonrigidParams
from cpapfit.errors import InputError
from cpapfit.fusion import Frame, FusionParams, fuse
from cpapfit.synthetic.ict_sweep import make_ict_sweep
from cpapfit.io import load_scan
from cpapfit.io.phantom import write_sweep
from cpapfit.io.rsbag import read_bag
from cpapfit.io.sweep import frame_folders, read_frames
import cpapfit.pipeline as pipeline
from cpapfit.pipeline import align, register_template, registered_part
from cpapfit.synthetic.accuracy import surface_distance
from cpapfit.scan import Intrinsics
from cpapfit.template import load_template, mask_region
from realsense import write_bag


@pytest.fixture(scope="module")
def sweep():
    """Four frames of ICT subject 1, yaw -35 to +35 degrees."""
    return make_ict_sweep(1, 4)


@pytest.fixture(scope="module")
def sweep_dir(tmp_path_factory, sweep):
    folder = tmp_path_factory.mktemp("sweep")
    write_sweep(sweep, folder)
    return folder


@pytest.fixture(scope="module")
def fused(sweep_dir):
    return load_scan(sweep_dir)


def test_fused_sweep_lies_on_the_true_face(sweep, fused):
    """Every frame tracked; the true face (template vertices, frame 0's camera) within 0.3 mm median
    and 1.0 mm p95 of the fused surface, the contact bands too."""
    assert "fused 4 of 4 frames" in fused.units_note
    dist = surface_distance(sweep[0].surface, fused.vertices, fused.faces)
    band = dist[mask_region(load_template())]
    assert np.median(dist) < 0.3 and np.percentile(dist, 95) < 1.0
    assert np.median(band) < 0.3 and np.percentile(band, 95) < 1.0
    assert fused.colors is not None and fused.colors.std() > 5  # the colour is fused too


def frame(name: str, ph, depth_raw=None) -> Frame:
    """A phantom's capture as a sweep frame (its depth, or `depth_raw` in its units)."""
    raw = ph.depth_raw if depth_raw is None else depth_raw
    return Frame(name, np.where(raw > 0, raw * (1000.0 / ph.sensor.depth_scale), np.nan), ph.image, ph.intrinsics)


def camera_in_frame0(sweep, k: int) -> np.ndarray:
    """(4, 4) frame k's true camera-to-frame-0 transform (mm), from the synthetic poses."""
    def face_to_camera(ph):
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = ph.pose["rotation"], ph.pose["translation_mm"]
        return m
    return face_to_camera(sweep[0]) @ np.linalg.inv(face_to_camera(sweep[k]))


def test_only_the_head_is_fused_round_where_the_cameras_look(sweep):
    """With an 80 mm ball and three of the four frames integrated, every fused point lies within
    80 mm of the point nearest the cameras' true optical axes, though the face reaches beyond it;
    the masks' contact bands on the true face are still covered."""
    fused = fuse(tuple(frame(f"{k}", ph) for k, ph in enumerate(sweep)),
                 FusionParams(voxel_mm=2.0, truncation_mm=6.0, head_mm=80.0, max_integrated=3))
    cameras = [camera_in_frame0(sweep, k) for k in (0, 2, 3)]  # the three integrated: spread from first to last
    across = [np.eye(3) - np.outer(c[:3, 2], c[:3, 2]) for c in cameras]
    centre = np.linalg.solve(sum(across), sum(a @ c[:3, 3] for a, c in zip(across, cameras)))
    assert np.linalg.norm(fused.vertices - centre, axis=1).max() < 80.0 + 2.0
    assert np.linalg.norm(sweep[0].surface - centre, axis=1).max() > 95.0
    band = surface_distance(sweep[0].surface, fused.vertices, fused.faces)[mask_region(load_template())]
    assert np.percentile(band, 95) < 1.0


def test_a_fused_sweep_is_registered_on_its_face_and_not_the_rest_of_the_head(sweep, sweep_dir, fused, monkeypatch):
    """The template is registered on the fused triangles whose corners lie within 90 mm (times the
    face's scale) of its mask region's centre, each with its corners' colours: that part still
    covers the true face's contact bands (p95 under 1 mm) and leaves out the fused surface beyond,
    which reaches 15 mm further; one frame's capture is registered whole."""
    al = align(fused)
    aligned = al.similarity.apply(load_template().vertices)
    reach = NonrigidParams().fused_reach_mm * al.similarity.scale
    centre = aligned[mask_region(load_template())].mean(axis=0)
    seen = []
    monkeypatch.setattr(pipeline, "register", lambda aligned, faces, scan, *rest: seen.append(scan))
    register_template(fused, al)
    part = seen[0]
    inside = (np.linalg.norm(fused.vertices[fused.faces] - centre, axis=2) <= reach).all(axis=1)
    assert fused.fused_frames == 4 and 0 < inside.sum() < len(fused.faces)
    assert np.array_equal(part.vertices[part.faces], fused.vertices[fused.faces[inside]])
    assert np.array_equal(part.colors[part.faces], fused.colors[fused.faces[inside]])
    assert np.array_equal(part.normals[part.faces], fused.normals[fused.faces[inside]])
    assert np.linalg.norm(fused.vertices - centre, axis=1).max() > reach + 15.0
    band = surface_distance(sweep[0].surface, part.vertices, part.faces)[mask_region(load_template())]
    assert np.percentile(band, 95) < 1.0
    one = load_scan(frame_folders(sweep_dir)[0])
    assert one.fused_frames == 0 and registered_part(one, aligned, al.similarity.scale) is one


def test_frames_named_with_unpadded_numbers_are_fused_in_their_numbers_order(sweep_dir, fused, tmp_path):
    """The sweep's four frames renamed frame_8 to frame_11 (by name, frame_10 would come first)
    fuse to the very same surface as the folder as written."""
    renamed = tmp_path / "renamed"
    renamed.mkdir()
    for k, folder in enumerate(frame_folders(sweep_dir)):
        shutil.copytree(folder, renamed / f"frame_{8 + k}")
    assert [p.name for p in frame_folders(renamed)] == ["frame_8", "frame_9", "frame_10", "frame_11"]
    again = load_scan(renamed)
    assert again.vertices.shape == fused.vertices.shape and np.array_equal(again.vertices, fused.vertices)


def test_frames_without_depth_and_of_another_scene_are_dropped_with_a_note(sweep):
    """Frame 1 with no depth, a frame of a tilted wall put in after frame 2: both dropped, each said
    why; the rest fused (a coarse volume, for time) onto the true face."""
    rows = np.arange(sweep[2].depth_raw.shape[0])[:, None]
    wall = np.broadcast_to(3000 + 2 * rows, sweep[2].depth_raw.shape)  # 0.1 mm units: 300-396 mm away
    frames = (frame("0", sweep[0]), frame("1", sweep[1], np.zeros_like(sweep[1].depth_raw)), frame("2", sweep[2]),
              frame("wall", sweep[2], wall), frame("3", sweep[3]))
    fused = fuse(frames, FusionParams(voxel_mm=2.0, truncation_mm=6.0))
    assert fused.kept == ("0", "2", "3")
    assert "frame 1 dropped: no depth" in fused.note() and "frame wall dropped: not tracked" in fused.note()
    dist = surface_distance(sweep[0].surface, fused.vertices, fused.faces)
    assert np.median(dist) < 0.5


def test_a_sweep_that_cannot_be_tracked_is_refused():
    """Frames of unrelated random surfaces: no two fit, one clear InputError."""
    intr = Intrinsics(40, 30, 35.0, 35.0, 19.5, 14.5)
    rng = np.random.default_rng(0)
    frames = tuple(Frame(f"{k:03d}", 400.0 + 150.0 * rng.uniform(size=(30, 40)), None, intr) for k in range(4))
    with pytest.raises(InputError, match="cannot be tracked"):
        fuse(frames)


def test_mixed_resolutions_are_refused_in_one_line(sweep_dir, tmp_path, cli):
    folder = tmp_path / "mixed"
    shutil.copytree(sweep_dir, folder)
    for path in sorted((folder / "003").iterdir()):
        if path.name.endswith(".png"):
            Image.open(path).resize((320, 240)).save(path)
    (folder / "003" / "intrinsics.json").write_text(
        '{"width": 320, "height": 240, "intrinsic_matrix": [300, 0, 0, 0, 300, 0, 159.5, 119.5, 1], "depth_scale": 10000}')
    code, out, err = cli("design", folder, "--out", tmp_path / "out")
    assert code == 2 and err.count("\n") == 1 and "frame 003 is 320x240" in err
    assert not (tmp_path / "out").exists()


def test_a_realsense_recording_is_read_and_fused_as_the_sweep_folder_it_was_made_from(sweep, sweep_dir, fused, tmp_path):
    """The sweep recorded by librealsense (a software device): the same frames (depth within one
    depth unit, the colour at every valid depth pixel), intrinsics (float32) and depth scale as
    the folder, the same again when read again, and its fused surface on the folder's (median under
    0.1 mm); recorded without colour, the same depth and no colour."""
    bag = write_bag(sweep, tmp_path / "take.bag")
    (frames, scales), (folder_frames, folder_scales) = read_bag(bag), read_frames(sweep_dir)
    assert scales == folder_scales == {10000.0} and [f.name for f in frames] == [f.name for f in folder_frames]
    for frame, truth in zip(frames, folder_frames):
        k, k_truth = frame.intrinsics, truth.intrinsics
        assert np.allclose([k.width, k.height, k.fx, k.fy, k.cx, k.cy],
                           [k_truth.width, k_truth.height, k_truth.fx, k_truth.fy, k_truth.cx, k_truth.cy], atol=1e-4)
        valid = np.isfinite(truth.depth)
        assert (np.isfinite(frame.depth) == valid).all() and valid.sum() > 50_000
        assert np.abs(frame.depth - truth.depth)[valid].max() <= 1000.0 / 10000.0
        assert (frame.image[valid] == truth.image[valid]).all()
    again, _ = read_bag(bag)  # played back not in real time: every frame, the same each time
    assert all(np.array_equal(f.depth, g.depth, equal_nan=True) and np.array_equal(f.image, g.image) for f, g in zip(frames, again))
    scan = load_scan(bag)
    assert "fused 4 of 4 frames" in scan.units_note and "depth_scale 10000 " in scan.units_note
    assert np.median(surface_distance(scan.vertices, fused.vertices, fused.faces)) < 0.1
    assert abs(len(scan.vertices) - len(fused.vertices)) < 0.01 * len(fused.vertices)
    depth_only, _ = read_bag(write_bag(sweep, tmp_path / "depth.bag", color=False))
    assert all(f.image is None and np.array_equal(f.depth, g.depth, equal_nan=True) for f, g in zip(depth_only, frames))


def test_broken_realsense_recordings_are_refused_in_one_line(sweep, tmp_path, cli):
    """A truncated recording, one that is no recording, one without depth and one of two frames:
    one line each, exit 2, no design folder."""
    whole = write_bag(sweep, tmp_path / "whole.bag").read_bytes()
    (tmp_path / "cut.bag").write_bytes(whole[: len(whole) // 2])
    (tmp_path / "zeros.bag").write_bytes(b"\0" * 64)
    write_bag(sweep, tmp_path / "colour.bag", depth=False)
    write_bag(sweep[:2], tmp_path / "two.bag")
    for name, says in (("cut", "not a readable RealSense recording"), ("zeros", "not a readable RealSense recording"),
                       ("colour", "no depth stream"), ("two", "2 depth frames recorded; a sweep needs at least 3")):
        code, out, err = cli("design", tmp_path / f"{name}.bag", "--out", tmp_path / name)
        assert code == 2 and err.count("\n") == 1 and says in err, (name, err)
        assert not (tmp_path / name).exists()


def test_open3d_is_imported_only_to_fuse_a_sweep():
    """The command line and its commands do not pay Open3D's import (seconds), nor pyrealsense2's."""
    code = "import sys, cpapfit.cli, cpapfit.commands, cpapfit.api; sys.exit('open3d' in sys.modules or 'pyrealsense2' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_phantom_frames_needs_the_ict_population(cli, tmp_path):
    code, out, err = cli("phantom", "--seed", 1, "--frames", 4, "--population", "template", "--out", tmp_path / "s")
    assert code == 2 and "--frames" in err and not (tmp_path / "s").exists()
