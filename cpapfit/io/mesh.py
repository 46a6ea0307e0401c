"""Mesh scans in: PLY, OBJ (with texture), STL, OFF, GLB, as trimesh reads them."""

from pathlib import Path

import numpy as np
import trimesh

from ..errors import InputError
from ..rims import edge_uses, same_position
from ..scan import Scan, texels
from ..winding import wound_against
from .normals import cloud_normals
from .limits import check_complete, check_declared_size, check_size
from .surface import MIN_SHARED_EDGES, check_surface
from .units import MM_PER_UNIT, decide_units
from ..thresholds import MIN_VERTICES

MESH_SUFFIXES = (".ply", ".obj", ".stl", ".off", ".glb", ".gltf")


def load_mesh_scan(path: Path, units: str = "auto") -> Scan:
    """Read a mesh or point-cloud file into a `Scan` in millimetres (the file's own frame)."""
    geom = read_geometry(path)
    vertices, faces, (colors, texture, uv), uses = _welded(*_arrays(path, geom))
    _check(path, vertices, faces, uses)
    unit, note = decide_units(vertices, units)
    vertices = vertices * MM_PER_UNIT[unit]
    if len(faces):
        faces, normals = _wound_alike(vertices, faces)
    else:
        normals = cloud_normals(vertices)
    return Scan(
        vertices=vertices, faces=faces, normals=normals, source=str(path), units=unit, units_note=note,
        colors=colors, texture=texture, uv=uv,
    )


def read_geometry(path: Path):
    """One trimesh geometry (Trimesh or PointCloud) from a file, or an InputError."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such file")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: the file is empty")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(f"{path}: not a mesh file ({', '.join(MESH_SUFFIXES)}) nor an RGB-D capture folder")
    if path.suffix.lower() == ".obj":
        _check_obj_tail(path)
    declared = check_declared_size(path)
    try:
        loaded = _parse(path)
    except InputError:
        raise
    except Exception as exc:  # any parser failure on a user's file is a bad file
        raise InputError(
            f"{path}: not a readable {path.suffix.lstrip('.').upper()} mesh ({type(exc).__name__}: {exc}); "
            "is the file complete and of that format?"
        ) from None
    check_complete(path, declared, len(loaded.vertices), len(getattr(loaded, "faces", ())))
    return loaded


def _parse(path: Path):
    """trimesh's reading of a file as one geometry: a scene's meshes joined, an STL's corners merged."""
    loaded = trimesh.load(path, process=False)
    if isinstance(loaded, trimesh.Scene):
        geoms = [g for g in loaded.dump() if hasattr(g, "vertices")] if loaded.geometry else []
        if not geoms:
            raise InputError(f"{path}: the file holds no mesh")
        loaded = trimesh.util.concatenate(geoms) if len(geoms) > 1 else geoms[0]
    if path.suffix.lower() == ".stl" and isinstance(loaded, trimesh.Trimesh):
        loaded.merge_vertices()  # STL stores every triangle's corners separately
    return loaded


def companion_files(path: Path) -> list[Path]:
    """The files an OBJ is read with besides itself: its material libraries and their texture maps
    (those that exist); none for other formats."""
    path = Path(path)
    if path.suffix.lower() != ".obj":
        return []
    libraries = _named_files(path, ("mtllib",))
    return libraries + [t for lib in libraries for t in _named_files(lib, ("map_", "bump", "disp", "norm"))]


def _named_files(path: Path, keywords: tuple[str, ...]) -> list[Path]:
    """Existing files named (last word, relative to the folder) by the lines of a text file that
    start with one of `keywords`."""
    with open(path, encoding="latin-1") as fh:
        names = [line.split()[-1] for line in fh if line.startswith(keywords) and len(line.split()) > 1]
    return [path.parent / n for n in dict.fromkeys(names) if (path.parent / n).is_file()]


def _arrays(path: Path, geom):
    """(vertices (N, 3) float64, faces (M, 3) int64, (colors, texture, uv)) of a parsed file, or an
    InputError: trimesh builds some of these lazily, so a malformed file may fail only here."""
    try:
        vertices = np.asarray(geom.vertices, dtype=np.float64)
        faces = np.asarray(getattr(geom, "faces", np.zeros((0, 3))), dtype=np.int64)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or (faces.size and (faces.ndim != 2 or faces.shape[1] != 3)):
            raise ValueError(f"vertices {vertices.shape}, faces {faces.shape}")
        return vertices, faces.reshape(-1, 3), _appearance(geom, len(vertices))
    except Exception as exc:  # any failure to read a user's file is a bad file
        raise InputError(f"{path}: a malformed {path.suffix.lstrip('.').upper()} file ({type(exc).__name__}: {exc}); re-export the scan") from None


# OBJ statements and the fewest fields each needs; an OBJ (no counts in a header) cut short
# usually ends in the middle of one.
OBJ_FIELDS = {"v": 3, "vt": 2, "vn": 3, "f": 3, "l": 2}


def _check_obj_tail(path: Path) -> None:
    """Refuse an OBJ whose last statement is incomplete or lacks its end of line (a truncated upload)."""
    with open(path, "rb") as fh:
        fh.seek(max(0, path.stat().st_size - 4096))
        tail = fh.read()
    lines = tail.decode("latin-1").strip().splitlines()
    fields = lines[-1].split() if lines else []
    if not fields:
        return
    need = OBJ_FIELDS.get(fields[0], 0)
    unended = need and not tail.endswith((b"\n", b"\r"))
    if len(fields) - 1 < need or (fields[0] == "f" and fields[-1].endswith("/")) or unended:
        raise InputError(f"{path}: the last line '{lines[-1][:40]}' is cut short; the file is truncated")


def _welded(vertices: np.ndarray, faces: np.ndarray, appearance: tuple):
    """A triangle soup (every triangle with its own corners, as some exporters write) or a point
    cloud with the corners or points at one position joined into one, its colour their mean (a
    texture is sampled at each corner first); any other mesh unchanged. A cloud's repeated points
    would hide its rims and its normals. Returns (vertices, faces, (colors, texture, uv), uses: (E,)
    how many of the faces use each of their edges, `edge_uses`; None without faces)."""
    uses = edge_uses(faces)[1] if len(faces) else None
    if uses is not None and (uses == 2).mean() >= MIN_SHARED_EDGES:
        return vertices, faces, appearance, uses
    colors, texture, uv = appearance
    rgb = colors / 255.0 if colors is not None else None
    if texture is not None:
        rgb = texels(texture, uv)
    joined, first, index = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # the joined vertices in the file's order
    index = np.argsort(order)[index.ravel()]
    if rgb is not None:
        rgb = np.stack([np.bincount(index, rgb[:, k], len(order)) for k in range(3)], axis=1) / np.bincount(index)[:, None]
        rgb = np.round(255.0 * rgb).astype(np.uint8)
    faces = index[faces]
    return joined[order], faces, (rgb, None, None), edge_uses(faces)[1] if len(faces) else None


def _check(path: Path, vertices: np.ndarray, faces: np.ndarray, uses: np.ndarray | None) -> None:
    """Refuse meshes no stage can use: too few or too many points, NaN/Inf, faces pointing nowhere,
    triangles that are no surface (`uses`: how many triangles use each edge, `edge_uses`)."""
    check_size(path, len(vertices), len(faces))
    if len(vertices) < MIN_VERTICES:
        raise InputError(f"{path}: only {len(vertices)} vertices; a face scan has thousands (is the file truncated?)")
    if not np.isfinite(vertices).all():
        bad = int((~np.isfinite(vertices)).any(axis=1).sum())
        raise InputError(f"{path}: {bad} vertices are NaN or infinite; repair or re-export the scan")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise InputError(f"{path}: triangles refer to vertices that do not exist; the file is corrupt")
    if len(faces):
        check_surface(path, vertices, faces, uses)


def _wound_alike(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((M, 3) faces, (N, 3) unit normals): the triangles wound against their neighbours turned to
    agree with them (`winding.py`; the file's winding where most of it agrees), and
    area-weighted vertex normals over every triangle at a vertex's position (the copies of a vertex
    on a texture seam share one normal). A mesh wound one way on one side and the other on the
    other had normals that disagreed across the face, and the registration dropped half of it."""
    same = same_position(vertices)
    joined = np.zeros((int(same.max()) + 1, 3))
    joined[same] = vertices
    faces = np.where(wound_against(same[faces])[:, None], faces[:, ::-1], faces)
    mesh = trimesh.Trimesh(joined, same[faces], process=False)
    return faces, np.array(mesh.vertex_normals, dtype=np.float64)[same]


def _appearance(geom, n: int):
    """(colors, texture, uv): per-vertex colour, or texture image and coordinates, if the file has them."""
    if isinstance(geom, trimesh.PointCloud):
        colors = np.asarray(geom.colors)
        return (colors[:, :3].astype(np.uint8) if len(colors) == n else None), None, None
    visual = getattr(geom, "visual", None)
    kind = getattr(visual, "kind", None)
    if kind in ("vertex", "face"):  # face colours (a PLY's): each vertex the mean of its triangles' (trimesh)
        return np.asarray(visual.vertex_colors)[:, :3].astype(np.uint8), None, None
    if kind == "texture" and visual.uv is not None and len(visual.uv) == n:
        image = getattr(visual.material, "image", None) or getattr(visual.material, "baseColorTexture", None)
        if image is not None:
            return None, np.asarray(image.convert("RGB")), np.asarray(visual.uv, dtype=np.float64)
    return None, None, None
