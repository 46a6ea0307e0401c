"""A synthetic subject on disk: an RGB-D capture folder or a head mesh, plus its ground truth."""

from dataclasses import asdict
from pathlib import Path

import numpy as np
import trimesh

from .. import __version__
from ..synthetic.ict_phantom import HeadMesh
from ..synthetic.camera import Phantom
from ..rgbd import project
from ..template import N_LANDMARKS, load_template
from .capture import capture_files
from .write import json_bytes, ply_bytes, write_files

TRUTH = "ground_truth"
HEAD = "head.ply"


def truth_files(surface: np.ndarray, faces: np.ndarray, frame: str, subject: dict, pixels: np.ndarray | None = None) -> dict[str, bytes]:
    """{relative name: bytes} of a subject's truth: ground_truth/surface.ply ((N, 3) mm template-order
    `surface` with (M, 3) `faces`, in `frame`), ground_truth/landmarks.json (its first 468 vertices,
    and their (468, 2) image `pixels` if given) and ground_truth/subject.json (`subject`)."""
    landmarks = {
        "units": "mm", "frame": frame,
        "points": np.round(surface[:N_LANDMARKS], 6).tolist(),
        "template_index": list(range(N_LANDMARKS)),
    }
    if pixels is not None:
        landmarks["pixels"] = np.round(pixels, 3).tolist()
    return {
        f"{TRUTH}/surface.ply": ply_bytes(surface, faces),
        f"{TRUTH}/landmarks.json": json_bytes(landmarks),
        f"{TRUTH}/subject.json": json_bytes(subject),
    }


def phantom_files(ph: Phantom) -> dict[str, bytes]:
    """{relative name: bytes} of the capture (color.png, depth.png, intrinsics.json) and its truth
    (`truth_files`: camera frame; subject.json holds seed, identity, pose, sensor model)."""
    files = capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale)
    subject = {"seed": ph.seed, "cpapfit_version": __version__, "identity": ph.identity, "pose": ph.pose, "sensor": asdict(ph.sensor)}
    files.update(truth_files(ph.surface, ph.faces, "camera (x right, y down, z forward)", subject,
                             project(ph.landmarks, ph.intrinsics)))
    return files


def sweep_files(sweep: tuple[Phantom, ...]) -> dict[str, bytes]:
    """{relative name: bytes} of a synthetic sweep: frame k's capture in NNN/ (k with three digits)
    and the truth (`truth_files`) in frame 0's camera frame; subject.json holds seed, identity,
    sensor and every frame's pose."""
    first = sweep[0]
    files = {f"{k:03d}/{name}": data for k, ph in enumerate(sweep)
             for name, data in capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale).items()}
    subject = {"seed": first.seed, "cpapfit_version": __version__, "identity": first.identity,
               "sensor": asdict(first.sensor), "frames": [ph.pose for ph in sweep]}
    files.update(truth_files(first.surface, first.faces, "frame 000's camera (x right, y down, z forward)", subject,
                             project(first.landmarks, first.intrinsics)))
    return files


def head_mesh_files(head: HeadMesh) -> dict[str, bytes]:
    """{relative name: bytes} of a head mesh scan (head.ply: mm, vertex colours) and its truth
    (`truth_files`, the mesh's frame; subject.json holds seed and identity)."""
    subject = {"seed": head.seed, "cpapfit_version": __version__, "identity": head.identity}
    files = {HEAD: trimesh.exchange.ply.export_ply(head.mesh, encoding="binary")}
    files.update(truth_files(head.truth, load_template().faces, "template (x to the subject's left, y up, z out of the face)", subject))
    return files


def write_phantom(ph: Phantom, folder: Path) -> list[Path]:
    """Write a phantom's capture folder and ground truth (atomically, file by file)."""
    return write_files(Path(folder), phantom_files(ph))


def write_sweep(sweep: tuple[Phantom, ...], folder: Path) -> list[Path]:
    """Write a synthetic sweep's frames and ground truth (atomically, file by file)."""
    return write_files(Path(folder), sweep_files(sweep))


def write_head_mesh(head: HeadMesh, folder: Path) -> list[Path]:
    """Write a head mesh scan and its ground truth into a folder (atomically, file by file)."""
    return write_files(Path(folder), head_mesh_files(head))
