"""Files in and out: scans (meshes, RGB-D captures), units, atomic writes."""

from pathlib import Path

from ..errors import InputError, UnitsError
from ..scan import Scan
from .capture import is_capture, load_capture
from .mesh import load_mesh_scan


def load_scan(path: Path, units: str = "auto") -> Scan:
    """Read a mesh file or an RGB-D capture folder into a `Scan` in millimetres."""
    path = Path(path)
    if is_capture(path):
        if units != "auto":
            raise UnitsError(f"{path}: an RGB-D capture takes its units from depth_scale in intrinsics.json; drop --units")
        return load_capture(path)
    if not path.exists():
        raise InputError(f"{path}: no such file or folder")
    return load_mesh_scan(path, units)
