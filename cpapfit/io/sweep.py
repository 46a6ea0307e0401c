"""Sweeps: a folder of capture folders (frames in the order of their names, numbers read as numbers), fused into one mesh scan.

A sweep holds no color.png, depth.png or intrinsics.json of its own; each subfolder that does is a
frame (other subfolders, such as a synthetic sweep's ground_truth/, are not). The frames are one
camera: one resolution and one set of intrinsics. The fusion itself is `cpapfit.fusion`; a
RealSense recording (`rsbag.py`) is fused here too.
"""

import re
from pathlib import Path

import numpy as np
import trimesh

from ..errors import InputError
from ..scan import Scan
from .capture import read_frame
from .mesh import _wound_alike

FRAME_FILES = ("depth.png", "intrinsics.json")


def is_frame(path: Path) -> bool:
    """True when `path` is a folder with a depth image or intrinsics (a capture folder)."""
    return path.is_dir() and any((path / name).is_file() for name in FRAME_FILES)


def is_sweep(path: Path) -> bool:
    """True when `path` is a folder that is no capture itself but holds capture folders."""
    path = Path(path)
    return path.is_dir() and not is_frame(path) and any(is_frame(p) for p in path.iterdir())


def frame_folders(folder: Path) -> list[Path]:
    """The sweep's frame folders, in the order of their names, numbers within them read as numbers
    (`frame_2` before `frame_10`, as `frame_02` before `frame_10`)."""
    return sorted((p for p in Path(folder).iterdir() if is_frame(p)), key=lambda p: _in_order(p.name))


def _in_order(name: str) -> tuple:
    """A sort key of a name: its runs of digits as numbers (then as written, so that `2` and `02`
    keep one order), the text between them as text (text and digits alternate, from text)."""
    parts = re.split(r"(\d+)", name)
    return tuple((int(part), part) if k % 2 else part for k, part in enumerate(parts))


def read_frames(folder: Path):
    """The sweep's frames (`fusion.Frame`), in order; InputError for a sweep of mixed camera modes."""
    from ..fusion import Frame

    frames, scales, first = [], set(), None
    for path in frame_folders(folder):
        intr, depth_scale, depth, image = read_frame(path)
        first = first or (path.name, intr)
        if intr != first[1]:
            raise InputError(
                f"{folder}: frame {path.name} is {intr.width}x{intr.height} (f {intr.fx:.1f} px) but frame "
                f"{first[0]} is {first[1].width}x{first[1].height} (f {first[1].fx:.1f} px); a sweep is one "
                "camera in one mode: put frames of other modes in a sweep of their own"
            )
        frames.append(Frame(path.name, depth, image, intr))
        scales.add(depth_scale)
    return tuple(frames), scales


def load_sweep(folder: Path) -> Scan:
    """A sweep folder fused into a mesh `Scan` (`fused_scan`)."""
    return fused_scan(*read_frames(folder), folder)


def fused_scan(frames, scales: set[float], source: Path) -> Scan:
    """The frames (`fusion.Frame`, in order, one camera; their depth_scales `scales`, units per
    metre) fused (`fusion.fuse`) into a mesh `Scan` (mm, the first fused frame's camera frame, vertex
    colours); the note says which frames were fused and which dropped, and why."""
    from ..fusion import fuse

    fused = fuse(frames)
    faces, normals = _wound_alike(fused.vertices, fused.faces)
    scale = ", ".join(f"{s:g}" for s in sorted(scales))
    return Scan(
        vertices=fused.vertices, faces=faces, normals=normals, source=str(source), units="mm",
        units_note=f"units: millimetres, from depth_scale {scale} units per metre; {fused.note()}",
        colors=fused.colors, fused_frames=len(fused.kept),
    )


def fused_ply(scan: Scan) -> bytes:
    """Binary PLY of a fused scan: (N, 3) mm vertices, triangles, vertex colours."""
    colors = np.column_stack([scan.colors, np.full(len(scan.colors), 255, np.uint8)])
    mesh = trimesh.Trimesh(scan.vertices, scan.faces, vertex_colors=colors, process=False)
    return trimesh.exchange.ply.export_ply(mesh, encoding="binary")
