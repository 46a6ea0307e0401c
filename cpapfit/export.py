"""Printable solids: checks before anything is written, and the file formats (STL, 3MF in mm)."""

import io
import re
import zipfile

import manifold3d
import numpy as np
import trimesh

from .errors import CpapfitError


class SolidError(CpapfitError):
    """A designed solid failed a printability check: nothing is written."""


def check_closed(mesh: trimesh.Trimesh, name: str) -> None:
    """A part must be watertight, consistently wound, a valid manifold and of positive volume."""
    m = manifold3d.Manifold(manifold3d.Mesh(vert_properties=mesh.vertices.astype(np.float32), tri_verts=mesh.faces.astype(np.uint32)))
    if not (mesh.is_watertight and mesh.is_winding_consistent and m.status() == manifold3d.Error.NoError and mesh.volume > 0):
        raise SolidError(f"{name} is not a closed solid (watertight {mesh.is_watertight}, manifold {m.status().name}); nothing was written")


def check_solid(mesh: trimesh.Trimesh, wall_mm: float, min_wall_mm: float, name: str) -> dict:
    """Check a solid before it is written: watertight and consistently wound (trimesh), a valid
    manifold (manifold3d), positive volume, and its measured thinnest wall `wall_mm` at least
    95 % of `min_wall_mm`. Returns the measured values; raises SolidError otherwise."""
    m = manifold3d.Manifold(manifold3d.Mesh(vert_properties=mesh.vertices.astype(np.float32), tri_verts=mesh.faces.astype(np.uint32)))
    status = m.status()
    found = {
        "watertight": bool(mesh.is_watertight), "winding_consistent": bool(mesh.is_winding_consistent),
        "manifold3d": status.name, "volume_mm3": float(mesh.volume), "min_wall_mm": float(wall_mm),
    }
    ok = found["watertight"] and found["winding_consistent"] and status == manifold3d.Error.NoError and found["volume_mm3"] > 0
    if not ok or wall_mm < 0.95 * min_wall_mm:
        raise SolidError(f"{name} fails the printability checks ({found}); nothing was written")
    return found


def stl_bytes(mesh: trimesh.Trimesh) -> bytes:
    """Binary STL (mm)."""
    return trimesh.exchange.stl.export_stl(mesh)


def threemf_bytes(mesh: trimesh.Trimesh, name: str) -> bytes:
    """3MF with unit millimetre. trimesh's writer names objects with random UUIDs; they are
    replaced by fixed ones so that the same solid gives the same bytes."""
    raw = trimesh.exchange.threemf.export_3MF(trimesh.Scene({name: mesh}))
    out = io.BytesIO()
    with zipfile.ZipFile(io.BytesIO(raw)) as src, zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            data = src.read(info.filename)
            if info.filename.endswith(".model"):
                data = _fixed_uuids(data)
            dst.writestr(zipfile.ZipInfo(info.filename, date_time=(1980, 1, 1, 0, 0, 0)), data)
    return out.getvalue()


def _fixed_uuids(model: bytes) -> bytes:
    seen: dict[bytes, bytes] = {}

    def fixed(match):
        return seen.setdefault(match.group(0), b"00000000-0000-4000-8000-%012d" % len(seen))

    return re.sub(rb"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}", fixed, model)
