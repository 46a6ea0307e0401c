"""RGB-D capture folders: color.png|jpg, 16-bit depth.png and intrinsics.json (Open3D form).

intrinsics.json: {"width": W, "height": H, "intrinsic_matrix": [9 numbers, column-major],
"depth_scale": depth units per metre (optional, default 1000)}.
"""

import json
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from ..errors import InputError
from ..rgbd import backproject, grid_triangles
from ..scan import Intrinsics, Scan
from .write import json_bytes, png_bytes
from ..thresholds import MIN_VALID_PIXELS, DEPTH_RANGE_MM

COLOR_NAMES = ("color.png", "color.jpg", "color.jpeg")


def is_capture(path: Path) -> bool:
    """True when `path` is a folder (a capture, valid or not)."""
    return Path(path).is_dir()


def load_capture(folder: Path, depth_range_mm: tuple[float, float] = DEPTH_RANGE_MM) -> Scan:
    """Read a capture folder into a `Scan`: valid depth back-projected and triangulated, in mm."""
    folder = Path(folder)
    intr, depth_scale, depth, image = read_frame(folder, depth_range_mm)
    valid = np.isfinite(depth)
    if valid.sum() < MIN_VALID_PIXELS:
        raise InputError(
            f"{folder}: only {int(valid.sum())} depth pixels are valid ({depth_range_mm[0]:.0f}-"
            f"{depth_range_mm[1]:.0f} mm); the depth image is empty or in the wrong depth_scale"
        )
    pixel_vertex, faces = grid_triangles(depth, valid, intr)
    vertices = backproject(depth, intr)[valid]
    normals = _normals_towards_camera(vertices, faces)
    return Scan(
        vertices=vertices, faces=faces, normals=normals, source=str(folder), units="mm",
        units_note=f"units: millimetres, from depth_scale {depth_scale:g} units per metre",
        colors=image[valid] if image is not None else None, image=image, depth=depth, valid=valid,
        pixel_vertex=pixel_vertex, intrinsics=intr,
    )


def read_frame(folder: Path, depth_range_mm: tuple[float, float] = DEPTH_RANGE_MM):
    """(Intrinsics, depth_scale, (H, W) float64 depth mm with NaN where invalid or outside
    `depth_range_mm`, (H, W, 3) uint8 colour or None) of a capture folder."""
    intr, depth_scale = read_intrinsics(folder / "intrinsics.json")
    raw = _read_depth(folder / "depth.png")
    if raw.shape != (intr.height, intr.width):
        raise InputError(
            f"{folder}: depth.png is {raw.shape[1]}x{raw.shape[0]} but intrinsics.json says "
            f"{intr.width}x{intr.height}; the intrinsics belong to another camera mode"
        )
    return intr, depth_scale, depth_mm(raw, depth_scale, depth_range_mm), _read_color(folder, raw.shape)


def depth_mm(raw: np.ndarray, depth_scale: float, depth_range_mm: tuple[float, float] = DEPTH_RANGE_MM) -> np.ndarray:
    """(H, W) float64 mm of (H, W) uint16 raw depth in units of 1/depth_scale m; NaN where 0 (no
    depth), 65535 (saturated) or outside `depth_range_mm`."""
    depth = raw.astype(np.float64) * (1000.0 / depth_scale)
    valid = (raw > 0) & (raw < 65535) & (depth >= depth_range_mm[0]) & (depth <= depth_range_mm[1])
    depth[~valid] = np.nan
    return depth


def read_intrinsics(path: Path) -> tuple[Intrinsics, float]:
    """(Intrinsics, depth_scale) from an Open3D PinholeCameraIntrinsic JSON file."""
    if not path.is_file():
        raise InputError(f"{path}: missing; a capture folder needs color, depth.png and intrinsics.json")
    try:
        data = json.loads(path.read_text())
        w, h = int(data["width"]), int(data["height"])
        k = np.asarray(data["intrinsic_matrix"], dtype=np.float64).reshape(3, 3).T  # column-major
        depth_scale = float(data.get("depth_scale", 1000.0))
    except (ValueError, KeyError, TypeError, UnicodeDecodeError, RecursionError, OverflowError) as exc:
        raise InputError(
            f"{path}: not Open3D intrinsics ({type(exc).__name__}: {exc}); expected width, height, "
            "intrinsic_matrix (9 numbers, column-major) and optional depth_scale"
        ) from None
    if np.isfinite(k).all() and not np.allclose(k[2], [0.0, 0.0, 1.0]):
        stored = "row-major: store it column-major, as Open3D does" if np.allclose(k[:, 2], [0.0, 0.0, 1.0]) else "not a camera matrix"
        raise InputError(f"{path}: intrinsic_matrix's last row is {k[2].tolist()}, not [0, 0, 1] (read column-major); it is {stored}")
    intr = Intrinsics(width=w, height=h, fx=k[0, 0], fy=k[1, 1], cx=k[0, 2], cy=k[1, 2])
    plausible = (
        np.isfinite(k).all() and w > 0 and h > 0 and intr.fx > 0 and intr.fy > 0
        and 0 <= intr.cx <= w and 0 <= intr.cy <= h and np.isfinite(depth_scale) and depth_scale > 0
    )
    if not plausible:
        raise InputError(f"{path}: impossible intrinsics (focal lengths must be > 0, the principal point inside the image, depth_scale > 0)")
    return intr, depth_scale


def _open_image(path: Path) -> Image.Image:
    try:
        img = Image.open(path)
        img.load()
    except (OSError, SyntaxError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the image ({exc}); is the file complete?") from None
    return img


def _read_depth(path: Path) -> np.ndarray:
    """(H, W) uint16 raw depth from a 16-bit single-channel PNG."""
    if not path.is_file():
        raise InputError(f"{path}: missing; a capture folder needs color, depth.png and intrinsics.json")
    img = _open_image(path)
    if img.mode not in ("I;16", "I;16B", "I", "I;16L"):
        raise InputError(f"{path}: depth must be a 16-bit single-channel PNG, this one is mode {img.mode}")
    return np.asarray(img).astype(np.uint16)


def _read_color(folder: Path, shape: tuple[int, int]) -> np.ndarray | None:
    """(H, W, 3) uint8 colour image registered to the depth image, or None if the folder has none."""
    path = next((folder / n for n in COLOR_NAMES if (folder / n).is_file()), None)
    if path is None:
        return None
    image = np.asarray(_open_image(path).convert("RGB"))
    if image.shape[:2] != shape:
        raise InputError(
            f"{path}: colour is {image.shape[1]}x{image.shape[0]} but depth is {shape[1]}x{shape[0]}; "
            "register the colour image to the depth image first"
        )
    return image


def _normals_towards_camera(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(N, 3) unit vertex normals facing the camera; points without triangles get the view direction."""
    normals = np.array(trimesh.Trimesh(vertices, faces, process=False).vertex_normals, dtype=np.float64)
    lonely = np.linalg.norm(normals, axis=1) < 0.5
    normals[lonely] = -vertices[lonely] / np.linalg.norm(vertices[lonely], axis=1, keepdims=True)
    flip = np.einsum("ij,ij->i", normals, vertices) > 0
    normals[flip] *= -1
    return normals


def capture_files(image: np.ndarray, depth_raw: np.ndarray, intrinsics: Intrinsics, depth_scale: float) -> dict[str, bytes]:
    """The files of a capture folder, as {name: bytes}: color.png, depth.png, intrinsics.json."""
    k = intrinsics.matrix
    return {
        "color.png": png_bytes(image),
        "depth.png": png_bytes(depth_raw.astype(np.uint16)),
        "intrinsics.json": json_bytes({
            "width": intrinsics.width, "height": intrinsics.height,
            "intrinsic_matrix": k.T.reshape(-1).tolist(), "depth_scale": depth_scale,
        }),
    }
