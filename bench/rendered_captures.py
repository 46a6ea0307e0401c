"""A real mesh scan seen as RGB-D captures: each the scan rendered (its texture, depth in whole
millimetres by default, as most depth cameras store it) by a 640x480 camera of focal length 600 px
in front of the face its own design found, turned by a yaw and a pitch, then designed as a capture.

Printed per view: where the seal lands against the mesh's own design and against the mesh itself
(the true skin here), the rim gap, the coverage, the longest hole under the seal and the flags.
The renders have no sensor noise and no dropout: the views differ only in what the camera sees.

Usage: .venv/bin/python bench/rendered_captures.py [--scan FILE] [--mask nasal] [--distance 450]
       [--depth-scale 1000]   (the default scan, fran, needs ../shared)
"""

import argparse
import tempfile
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from cpapfit.errors import CpapfitError
from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.write import write_files
from cpapfit.landmarks.views import View, render_view
from cpapfit.pipeline import design, face_for
from cpapfit.render import scene_of
from cpapfit.scan import Intrinsics

FRAN = Path(__file__).resolve().parents[2] / "shared" / "data" / "fran_cyberware" / "fran.obj"
CAMERA = Intrinsics(640, 480, 600.0, 600.0, 319.5, 239.5)
POSES = ((0.0, 0.0), (20.0, 0.0), (-20.0, 0.0), (0.0, 15.0), (0.0, -15.0))  # (yaw, pitch) deg


def view_of(face, nose_tip: np.ndarray, distance: float, yaw: float, pitch: float) -> View:
    """The camera `distance` mm in front of the nose tip, looking against the face's axis, the head
    up the image, turned by yaw about the face's up and pitch about its left-right axis."""
    z = -face.axis
    y = -(face.up - (face.up @ z) * z)
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    turn = Rotation.from_rotvec(np.radians(yaw) * y).as_matrix() @ Rotation.from_rotvec(np.radians(pitch) * x).as_matrix()
    return View(np.stack([x, y, z]) @ turn.T, nose_tip, distance, CAMERA)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scan", type=Path, default=FRAN)
    ap.add_argument("--mask", default="nasal")
    ap.add_argument("--distance", type=float, default=450.0)
    ap.add_argument("--depth-scale", type=float, default=1000.0, help="depth units per metre (1000: whole mm)")
    args = ap.parse_args()
    mesh = load_scan(args.scan)
    own = design(mesh, args.mask)
    face = face_for(mesh, own.alignment, own.registration)
    skin = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    scene = scene_of(mesh.vertices, mesh.faces)
    print("| yaw | pitch | seal vs mesh design: mean | max (mm) | seal to the mesh: median | max (mm) | rim gap max (mm) | coverage | hole (mm) | flags |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for yaw, pitch in POSES:
        view = view_of(face, own.registration.vertices[4], args.distance, yaw, pitch)
        image, depth = render_view(mesh, view, scene)
        raw = np.where(np.isfinite(depth), np.round(depth * args.depth_scale / 1000.0), 0).astype(np.uint16)
        with tempfile.TemporaryDirectory() as tmp:
            write_files(Path(tmp), capture_files(image, raw, CAMERA, args.depth_scale))
            try:
                d = design(load_scan(Path(tmp)), args.mask)
            except CpapfitError as exc:
                print(f"| {yaw:g} | {pitch:g} | refused: {exc} |", flush=True)
                continue
        seal = view.to_scan(d.contact.curve)
        apart = cKDTree(seal).query(own.contact.curve)[0]
        on_skin = trimesh.proximity.closest_point(skin, seal)[1]
        gates = {g.code: g.value for g in d.quality.gates}
        rim = d.rim.summary()["rim_gap_max_mm"]
        print(f"| {yaw:g} | {pitch:g} | {apart.mean():.2f} | {apart.max():.2f} | {np.median(on_skin):.2f} | {on_skin.max():.2f} | "
              f"{'-' if rim is None else f'{rim:.2f}'} | {gates['coverage']:.2f} | {gates['hole_mm']:.0f} | "
              f"{' '.join(g.code for g in d.quality.flags)} |", flush=True)


if __name__ == "__main__":
    main()
