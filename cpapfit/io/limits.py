"""How big a mesh scan may be, checked from the file's header before it is parsed, and whether
the file holds what its header declares.

A face needs 10^4-10^6 vertices; a scan far larger is a whole body, a room, or a mistake, and
would take minutes and gigabytes. PLY and OFF headers and binary STL declare their counts, an
OBJ's are counted line by line (streamed); GLB is checked after parsing (it parses in a blink).
A binary STL whose size disagrees with its declared triangle count is truncated, and so is a PLY
or OFF file that parses to fewer vertices or faces than its header declares.
"""

from dataclasses import dataclass

import re
from pathlib import Path

from ..errors import InputError
from ..thresholds import MAX_VERTICES, MAX_TRIANGLES

STL_HEADER, STL_TRIANGLE = 84, 50  # binary STL: 80-byte header + uint32 count, 50 bytes a triangle
CHUNK = 1 << 24


def check_size(path: Path, n_vertices: int, n_triangles: int) -> None:
    """Refuse a scan with more than MAX_VERTICES vertices or MAX_TRIANGLES triangles."""
    if n_vertices > MAX_VERTICES or n_triangles > MAX_TRIANGLES:
        raise InputError(
            f"{path}: {n_vertices:,} vertices and {n_triangles:,} triangles; cpapfit reads at most {MAX_VERTICES:,} "
            f"and {MAX_TRIANGLES:,} (a face needs about 100,000): decimate or crop the scan to the face"
        )


@dataclass(frozen=True)
class Declared:
    """Counts a file declares (or that were counted in it); `exact`: the parsed file must hold them."""

    vertices: int
    faces: int
    exact: bool


def check_declared_size(path: Path) -> Declared | None:
    """Refuse, before parsing, a file whose header declares too many elements or a cut-short binary
    STL; return what it declares (None when the format does not say)."""
    suffix = path.suffix.lower()
    counts = {".ply": _ply_counts, ".off": _off_counts, ".stl": _stl_counts, ".obj": _obj_counts}.get(suffix)
    declared = counts(path) if counts else None
    if declared is not None:
        check_size(path, declared.vertices, declared.faces)
    return declared


def check_complete(path: Path, declared: Declared | None, n_vertices: int, n_triangles: int) -> None:
    """Refuse a parsed file holding fewer vertices or faces than its header declares (polygons
    become several triangles, so more triangles than faces is fine)."""
    if declared and declared.exact and (n_vertices < declared.vertices or n_triangles < declared.faces):
        raise InputError(
            f"{path}: the header declares {declared.vertices:,} vertices and {declared.faces:,} faces but the file "
            f"holds {n_vertices:,} and {n_triangles:,}; it is truncated"
        )


def _head(path: Path, size: int = 65536) -> str:
    with open(path, "rb") as fh:
        return fh.read(size).decode("latin-1")


def _ply_counts(path: Path) -> Declared | None:
    """Vertices and faces declared in a PLY header, or None if the header does not say."""
    head = _head(path).split("end_header")[0]
    counts = dict(re.findall(r"^element\s+(vertex|face)\s+(\d+)\s*$", head, flags=re.MULTILINE))
    return Declared(int(counts.get("vertex", 0)), int(counts.get("face", 0)), True) if counts else None


def _off_counts(path: Path) -> Declared | None:
    """Vertices and faces of an OFF file's count line, or None."""
    lines = [ln.split("#")[0].split() for ln in _head(path, 4096).splitlines()]
    words = [w for ln in lines for w in ln]
    if not words or not words[0].upper().endswith("OFF") or len(words) < 3:
        return None
    try:
        return Declared(int(words[1]), int(words[2]), True)
    except ValueError:
        return None


def _stl_counts(path: Path) -> Declared | None:
    """Vertices (after merging, about half the triangles) and triangles of a binary STL, or None for ASCII."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(STL_HEADER)
    if len(head) < STL_HEADER:
        return None
    triangles = int.from_bytes(head[80:84], "little")
    if size == STL_HEADER + STL_TRIANGLE * triangles:
        return Declared(triangles // 2, triangles, False)
    if not head.lstrip().startswith(b"solid"):
        raise InputError(
            f"{path}: a binary STL of {triangles:,} triangles should be {STL_HEADER + STL_TRIANGLE * triangles:,} bytes "
            f"but the file has {size:,}; it is truncated or not an STL"
        )
    return None


def _obj_counts(path: Path) -> Declared:
    """Vertices and faces of an OBJ: its 'v' and 'f' lines, counted chunk by chunk (not exact:
    texture seams may split vertices)."""
    vertices = faces = 0
    tail = b"\n"
    with open(path, "rb") as fh:
        while chunk := fh.read(CHUNK):
            text = tail + chunk
            vertices += text.count(b"\nv ") + text.count(b"\nv\t")
            faces += text.count(b"\nf ") + text.count(b"\nf\t")
            tail = text[-2:]  # a "\nv" split across chunks is counted in the next
    return Declared(vertices, faces, False)
