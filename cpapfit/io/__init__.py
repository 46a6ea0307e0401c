"""Files in and out: scans (meshes, RGB-D captures, sweeps, RealSense recordings), units, atomic writes."""

from pathlib import Path

from ..errors import InputError, UnitsError
from ..scan import Scan
from .capture import is_capture, load_capture
from .mesh import load_mesh_scan
from .rsbag import is_bag, read_bag
from .sweep import fused_scan, is_sweep, load_sweep


def load_scan(path: Path, units: str = "auto") -> Scan:
    """Read a mesh file, an RGB-D capture folder or a sweep (a folder of capture folders, or a
    RealSense recording: fused) into a `Scan` in millimetres."""
    path = Path(path)
    if is_bag(path):
        if units != "auto":
            raise UnitsError(f"{path}: a RealSense recording takes its units from its depth stream's depth scale; drop --units")
        return fused_scan(*read_bag(path), path)
    if is_sweep(path):
        if units != "auto":
            raise UnitsError(f"{path}: a sweep takes its units from depth_scale in its frames' intrinsics.json; drop --units")
        return load_sweep(path)
    if is_capture(path):
        if units != "auto":
            raise UnitsError(f"{path}: an RGB-D capture takes its units from depth_scale in intrinsics.json; drop --units")
        return load_capture(path)
    if not path.exists():
        raise InputError(f"{path}: no such file or folder")
    return load_mesh_scan(path, units)


def is_fused(path: Path) -> bool:
    """True when the scan at `path` is fused from depth frames: a sweep folder or a RealSense recording."""
    return is_bag(path) or is_sweep(path)
