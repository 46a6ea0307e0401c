"""A synthetic subject on disk: an RGB-D capture folder plus its ground truth."""

from dataclasses import asdict
from pathlib import Path

import numpy as np

from .. import __version__
from ..phantom import Phantom
from ..rgbd import project
from ..template import N_LANDMARKS
from .capture import capture_files
from .write import json_bytes, ply_bytes, write_files

TRUTH = "ground_truth"


def phantom_files(ph: Phantom) -> dict[str, bytes]:
    """{relative name: bytes} of the capture (color.png, depth.png, intrinsics.json) and its truth:
    ground_truth/surface.ply (template vertex order, camera frame, mm), ground_truth/landmarks.json
    and ground_truth/subject.json (seed, identity, pose, sensor model)."""
    files = capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale)
    files[f"{TRUTH}/surface.ply"] = ply_bytes(ph.surface, ph.faces)
    files[f"{TRUTH}/landmarks.json"] = json_bytes({
        "units": "mm", "frame": "camera (x right, y down, z forward)",
        "points": np.round(ph.landmarks, 6).tolist(),
        "template_index": list(range(N_LANDMARKS)),
        "pixels": np.round(project(ph.landmarks, ph.intrinsics), 3).tolist(),
    })
    files[f"{TRUTH}/subject.json"] = json_bytes({
        "seed": ph.seed, "cpapfit_version": __version__, "identity": ph.identity, "pose": ph.pose,
        "sensor": asdict(ph.sensor),
    })
    return files


def write_phantom(ph: Phantom, folder: Path) -> list[Path]:
    """Write a phantom's capture folder and ground truth (atomically, file by file)."""
    return write_files(Path(folder), phantom_files(ph))
