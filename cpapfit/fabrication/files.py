"""Printable solids as files: the checks before anything is written (the solid, and its file read
back as a slicer reads it), and the file formats (STL, 3MF in mm)."""

import io
import re
import zipfile
from xml.etree import ElementTree

import manifold3d
import numpy as np
import trimesh

from ..errors import CpapfitError
from ..rims import edge_uses
from ..solids import self_intersecting_edges, to_manifold, to_trimesh
from ..thresholds import WALL_TOLERANCE, ZERO_AREA_MM2


WELD_MM = 1e-5  # a part's vertices this close once rounded to float32 are merged (manifold3d simplify)
WELD_GROWTH = 10.0  # each further weld merges vertices this many times farther apart,
WELD_MAX_MM = 1e-3  # up to this (far under a printer's resolution)
PINCH_MM = 0.2  # where two sheets of a part touch along an edge, a bar this wide is cut out along it so that they part
CLEAN_PASSES = 3  # welds (and pinch cuts) a part gets at most to be clean as written
SLIVER_MM3 = 0.1  # a piece of a part smaller than this is a boolean's sliver, not material
STL_RECORD = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attributes", "<u2")])


class SolidError(CpapfitError):
    """A designed solid failed a printability check: nothing is written. `found`: the measured values."""

    def __init__(self, message: str, found: dict | None = None):
        super().__init__(message)
        self.found = found or {}


def check_closed(mesh: trimesh.Trimesh, name: str) -> dict:
    """A part must be watertight, consistently wound, a valid manifold (manifold3d), of positive
    volume and free of self-intersections. Returns the measured values; raises SolidError otherwise."""
    m = to_manifold(mesh)
    found = {
        "watertight": bool(mesh.is_watertight), "winding_consistent": bool(mesh.is_winding_consistent),
        "manifold3d": m.status().name, "volume_mm3": float(mesh.volume), "self_intersecting_edges": self_intersecting_edges(mesh),
    }
    if not (found["watertight"] and found["winding_consistent"] and m.status() == manifold3d.Error.NoError
            and found["volume_mm3"] > 0 and found["self_intersecting_edges"] == 0):
        raise SolidError(f"{name} is not a clean closed solid ({found}); nothing was written", found)
    return found


def check_solid(mesh: trimesh.Trimesh, wall_mm: float, min_wall_mm: float, name: str, membrane: tuple[float, float] | None = None) -> dict:
    """`check_closed`, and the measured thinnest wall `wall_mm` at least WALL_TOLERANCE of `min_wall_mm`;
    `membrane`: (measured thinnest mm, least share of its set thickness measured anywhere) of a
    membrane whose set thickness varies, the share held to the same tolerance."""
    found = check_closed(mesh, name) | {"min_wall_mm": float(wall_mm)}
    thin = wall_mm < WALL_TOLERANCE * min_wall_mm
    if membrane is not None:
        found["membrane_min_mm"] = float(membrane[0])
        thin |= membrane[1] < WALL_TOLERANCE
    if thin:
        raise SolidError(f"{name} fails the printability checks ({found}); nothing was written", found)
    return found


def checked_files(mesh: trimesh.Trimesh, name: str, formats: tuple[str, ...] = ("stl",), passed: list | None = None) -> dict[str, bytes]:
    """{"NAME.stl" | "NAME.3mf": bytes} of a part in each of `formats`, once each file read back as a
    slicer reads it (`read_stl`, `read_3mf_parts`) passes `check_file`; a file that reads back to the
    same vertices and triangles as one in `passed` (the meshes checked so far, added to) passes with it."""
    passed = [] if passed is None else passed
    files = {}
    for kind in formats:
        data = stl_bytes(mesh) if kind == "stl" else threemf_bytes(mesh, name)
        (back,) = [read_stl(data)] if kind == "stl" else read_3mf_parts(data)
        _check_once(back, f"{name}.{kind}", passed)
        files[f"{name}.{kind}"] = data
    return files


def checked_assembly(parts: dict[str, trimesh.Trimesh], name: str, passed: list | None = None) -> dict[str, bytes]:
    """{"NAME.3mf": bytes} of {part name: solid}, each where it lies, once every part read back as a
    slicer reads it passes `check_file` (`checked_files`' `passed`)."""
    passed = [] if passed is None else passed
    data = assembly_3mf_bytes(parts)
    for part, back in zip(parts, read_3mf_parts(data), strict=True):
        _check_once(back, f"{name}.3mf ({part})", passed)
    return {f"{name}.3mf": data}


def _check_once(back: trimesh.Trimesh, label: str, passed: list) -> None:
    """`check_file` of a mesh read back, unless one with the same vertices and triangles is in `passed`."""
    if not any(np.array_equal(back.vertices, p.vertices) and np.array_equal(back.faces, p.faces) for p in passed):
        check_file(back, label)
        passed.append(back)


def check_file(mesh: trimesh.Trimesh, name: str) -> dict:
    """A mesh file's triangles as re-read (`read_stl`, `read_3mf_parts`) must form a closed 2-manifold:
    every edge in exactly two triangles, no triangle under ZERO_AREA_MM2, and `check_closed`.
    Returns the measured values; raises SolidError otherwise."""
    found = {"edges_not_in_two_triangles": len(unpaired_edges(mesh)), "zero_area_triangles": int((mesh.area_faces < ZERO_AREA_MM2).sum())}
    if found["edges_not_in_two_triangles"] or found["zero_area_triangles"]:
        raise SolidError(f"{name} as written is not a closed 2-manifold ({found}); nothing was written", found)
    return found | check_closed(mesh, name)


def unpaired_edges(mesh: trimesh.Trimesh) -> np.ndarray:
    """(K, 2) the edges of a mesh not in exactly two of its triangles (vertex indices)."""
    edges, uses = edge_uses(mesh.faces)
    return edges[uses != 2]


def written_clean(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """`mesh` where its file reads back with no unpaired edge and no triangle under ZERO_AREA_MM2
    (`_reads_back_clean`), or where it is no valid closed solid (the checks at writing refuse it
    with its measured values); else `clean_as_written`: far from the origin float32 corners merge
    vertices that a boolean left microns apart (a scan 2 m from its origin)."""
    if _reads_back_clean(as_written(mesh)):
        return mesh
    solid = to_manifold(mesh)
    return clean_as_written(solid) if mesh.is_watertight and solid.status() == manifold3d.Error.NoError else mesh


def clean_as_written(part: manifold3d.Manifold) -> trimesh.Trimesh:
    """A part made clean as its float32 file reads back (`check_file`): `_welded`, and again while
    the file would still hold a triangle under ZERO_AREA_MM2 (a weld's output rounded to float32
    can leave two vertices one float32 step apart, or a sliver whose edges are a few steps long:
    3e-5 mm on a mould of an ICT head, which a weld at WELD_MM keeps) or two sheets touching along
    an edge (an edge of the file in four triangles: a bar PINCH_MM across is cut out along it
    first), at most CLEAN_PASSES times, each weld WELD_GROWTH times wider than the last, up to
    WELD_MAX_MM; what is left the check at writing refuses."""
    welded = _welded(part, WELD_MM)
    corners = PINCH_MM / 2 * np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    for attempt in range(1, CLEAN_PASSES + 1):
        written = as_written(to_trimesh(welded))
        if _reads_back_clean(written):
            break
        for ends in written.vertices[unpaired_edges(written)]:  # (2, 3) each
            welded = welded - manifold3d.Manifold.hull_points((ends[:, None] + corners).reshape(-1, 3))
        welded = _welded(welded, min(WELD_MM * WELD_GROWTH**attempt, WELD_MAX_MM))
    return to_trimesh(welded)


def _reads_back_clean(written: trimesh.Trimesh) -> bool:
    """A mesh as read back from its file has every edge in two triangles and none under ZERO_AREA_MM2."""
    return not len(unpaired_edges(written)) and written.area_faces.min(initial=np.inf) >= ZERO_AREA_MM2


def _welded(part: manifold3d.Manifold, tolerance_mm: float) -> manifold3d.Manifold:
    """A part with its vertices rounded to float32, as its file holds them, and those then within
    `tolerance_mm` (those that coincide) merged (manifold3d), dropping the slivers this parts from it
    (under SLIVER_MM3)."""
    welded = to_manifold(to_trimesh(part)).simplify(tolerance_mm)
    return manifold3d.Manifold.compose([body for body in welded.decompose() if body.volume() >= SLIVER_MM3])


def as_written(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """A mesh as its STL file is read back (`read_stl`)."""
    return read_stl(stl_bytes(mesh))


def read_stl(data: bytes) -> trimesh.Trimesh:
    """Binary STL bytes as a slicer reads them: each triangle's three float32 corners (mm), vertices
    merged by exact position (no tolerance, no repair)."""
    count = int.from_bytes(data[80:84], "little")
    return merged(np.frombuffer(data, STL_RECORD, count, offset=84)["corners"].reshape(-1, 3, 3))


def read_3mf_parts(data: bytes) -> list[trimesh.Trimesh]:
    """Each object of 3MF bytes as a slicer reads it: vertices parsed to float32 (mm), each
    triangle's corners by index, then vertices merged by exact position."""
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        root = ElementTree.fromstring(z.read("3D/3dmodel.model"))
    parts = []
    for mesh in root.iterfind(".//{*}mesh"):
        vertices = np.array([[v.get(k) for k in "xyz"] for v in mesh.iterfind(".//{*}vertex")], dtype=np.float32)
        faces = np.array([[t.get(k) for k in ("v1", "v2", "v3")] for t in mesh.iterfind(".//{*}triangle")], dtype=np.int64)
        parts.append(merged(vertices[faces]))
    return parts


def merged(corners: np.ndarray) -> trimesh.Trimesh:
    """(M, 3, 3) float32 triangle corners (mm) as a mesh whose vertices are the distinct positions."""
    vertices, index = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    return trimesh.Trimesh(vertices.astype(np.float64), index.reshape(-1, 3), process=False)


def stl_bytes(mesh: trimesh.Trimesh) -> bytes:
    """Binary STL (mm)."""
    return trimesh.exchange.stl.export_stl(mesh)


def threemf_bytes(mesh: trimesh.Trimesh, name: str) -> bytes:
    """3MF (unit millimetre) of one solid."""
    return assembly_3mf_bytes({name: mesh})


def assembly_3mf_bytes(parts: dict[str, trimesh.Trimesh]) -> bytes:
    """3MF with unit millimetre of {name: solid}, each part where it lies. trimesh's writer names
    objects with random UUIDs; they are replaced by fixed ones so that the same solids give the same bytes."""
    raw = trimesh.exchange.threemf.export_3MF(trimesh.Scene(parts))
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
