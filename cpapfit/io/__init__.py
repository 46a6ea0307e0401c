"""Files in and out: scans (meshes, RGB-D captures), units, atomic writes."""

from pathlib import Path

from ..errors import InputError, UnitsError
from ..scan import Scan
from .capture import is_capture, load_capture
from .mesh import load_mesh_scan
from .sweep import is_sweep, load_sweep


def load_scan(path: Path, units: str = "auto") -> Scan:
    """Read a mesh file, an RGB-D capture folder or a sweep (a folder of capture folders, fused)
    into a `Scan` in millimetres."""
    path = Path(path)
    if path.suffix.lower() == ".bag":
        raise InputError(
            f"{path}: RealSense recordings (.bag) are not read (pyrealsense2 is not installed with cpapfit); "
            "export its frames as capture folders (color.png, depth.png, intrinsics.json) into one folder, a sweep"
        )
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
