"""Atomic output: every file is written under a temporary name and renamed into place."""

import io
import json
import os
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image


def write_bytes(path: Path, data: bytes) -> None:
    """Write `data` to `path` atomically (temporary file in the same folder, then rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_files(folder: Path, files: dict[str, bytes]) -> list[Path]:
    """Write every {relative name: bytes} under `folder` atomically; all bytes exist before any write."""
    written = []
    for name, data in files.items():
        write_bytes(Path(folder) / name, data)
        written.append(Path(folder) / name)
    return written


RECORD_DIGITS = 10  # significant digits of a float in a design's records (fit.json and the like)


def json_bytes(obj) -> bytes:
    """Deterministic, readable JSON, every float as it is (files read back as input: a capture's
    intrinsics, a phantom's truth, landmarks)."""
    return (json.dumps(obj, indent=1, sort_keys=False) + "\n").encode()


def record_bytes(obj) -> bytes:
    """`json_bytes` of a computed record, every float to RECORD_DIGITS significant digits: the last
    bits of OpenBLAS's arithmetic (its AVX-512 kernels) vary with the arrays' memory alignment, so
    the same design made in another process could otherwise differ in its bytes."""
    return json_bytes(_rounded(obj))


def _rounded(obj):
    """`obj` with every float (in dicts, lists and tuples; numpy's float64 is one) to RECORD_DIGITS
    significant digits; NaN and infinities as they are."""
    if isinstance(obj, float):
        return float(f"{obj:.{RECORD_DIGITS}g}")
    if isinstance(obj, dict):
        return {k: _rounded(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_rounded(v) for v in obj]
    return obj


def png_bytes(image: np.ndarray) -> bytes:
    """PNG of an (H, W, 3) uint8 RGB image or an (H, W) uint16 image."""
    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="PNG")
    return buf.getvalue()


def ply_bytes(vertices: np.ndarray, faces: np.ndarray, attributes: dict | None = None) -> bytes:
    """Binary PLY of an (N, 3) mm mesh with (M, 3) faces, vertex order kept, optional (N,) vertex
    attributes written as extra vertex properties."""
    mesh = trimesh.Trimesh(vertices, faces, process=False, vertex_attributes=attributes or {})
    return trimesh.exchange.ply.export_ply(mesh, encoding="binary", include_attributes=bool(attributes))
