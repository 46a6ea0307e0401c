"""How repeatable each registration run is on one real face: several scans of it, both elastic runs
of each (from the affine and from the morphable start, `registration_starts.runs_of`), all brought
into one frame, and the runs' seal bands (both masks') compared there: each scan's bands against
the first scan's, and for each run (affine, morphable) and the registration `register_template`
makes of them ("kept": one run or a blend; a design may register again without landmarks it
drops) the mean distance (mm) between the same template vertices of two scans' bands, over every
pair of scans. No truth: a run that lands in the same
place on every scan of a face is repeatable, not necessarily right.

The scans: the shared mannequin sweep's (../shared/data/truedepth_sweep_mannequin), each "A-B"
(frames A to B fused, in that order: B < A runs backwards), "A-B/S" (every S-th) or "N" (frame N
alone, a capture), each fitted rigidly onto the first (the rigid fit of their affine runs'
vertices, then Open3D's point-to-plane ICP of the scan within 90 mm of the first scan's bands'
centre onto the first scan); or, with --scan FILE, a mesh scan and its renders as RGB-D captures from the five views of
`rendered_captures.py`, each brought back into the mesh's frame by its own camera's pose.

Usage: .venv/bin/python bench/start_repeatability.py [SCAN ...]   (default: the scans of RESULTS 2)
       .venv/bin/python bench/start_repeatability.py --scan FILE  (fran.obj: ../shared's fran)
"""

import itertools
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
import open3d as o3d

from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.write import write_files
from cpapfit.landmarks.views import render_view
from cpapfit.pipeline import face_for, place_template
from cpapfit.render import scene_of
from registration_starts import BANDS, runs_of
from rendered_captures import CAMERA, POSES, view_of

SWEEP = Path(__file__).resolve().parents[2] / "shared" / "data" / "truedepth_sweep_mannequin"
DEFAULT = ("0-89", "89-0", "0-59", "30-89", "0-89/2", "1-89/2", "20-69", "45", "80", "30", "60")
BAND = np.unique(np.concatenate(list(BANDS.values())))
NEAR_MM = 90.0


def scan_of(spec: str, frames: list[Path], tmp: Path):
    """The `Scan` a spec names (module docstring)."""
    whole = re.fullmatch(r"(\d+)-(\d+)(?:/(\d+))?", spec)
    if not whole:
        return load_scan(frames[int(spec)])
    a, b, step = int(whole[1]), int(whole[2]), int(whole[3] or 1)
    folder = tmp / spec.replace("/", "_")
    folder.mkdir()
    for i, j in enumerate(range(a, b + 1, step) if a <= b else range(a, b - 1, -step)):
        (folder / f"{i:03d}").symlink_to(frames[j])
    return load_scan(folder)


def kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(4, 4) rigid transform taking the (n, 3) points a nearest (least squares) onto b."""
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    rot = (u @ np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))]) @ vt).T
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, cb - rot @ ca
    return out


def cloud(points: np.ndarray, normals: np.ndarray | None = None) -> o3d.geometry.PointCloud:
    """An Open3D cloud of (n, 3) mm points (and their unit normals), copied from frozen arrays."""
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.array(points)))
    if normals is not None:
        pc.normals = o3d.utility.Vector3dVector(np.array(normals))
    return pc


def onto(scan, start: np.ndarray, reference: tuple) -> tuple[np.ndarray, float]:
    """(4, 4) transform of `scan` onto the reference scan (Open3D point-to-plane ICP from `start`,
    the scan's points within NEAR_MM of the reference's bands' centre) and the RMS distance (mm) of
    the pairs it kept (within 3 mm)."""
    ref_scan, ref_band = reference
    moved = scan.vertices @ start[:3, :3].T + start[:3, 3]
    near = np.linalg.norm(moved - ref_band.mean(axis=0), axis=1) < NEAR_MM
    target = cloud(ref_scan.vertices, ref_scan.normals)
    fit = o3d.pipelines.registration.registration_icp(
        cloud(scan.vertices[near]), target, 3.0, start, o3d.pipelines.registration.TransformationEstimationPointToPlane(),
        o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=60))
    return np.asarray(fit.transformation), fit.inlier_rmse


def sweep_scans(specs: list[str]):
    """(name, scan, None) of each sweep spec (module docstring); None: fitted onto the first by ICP."""
    if not SWEEP.is_dir():
        sys.exit(f"{SWEEP}: not found (the shared data)")
    frames = sorted(p for p in SWEEP.iterdir() if p.is_dir())
    with tempfile.TemporaryDirectory() as tmp:
        for spec in specs:
            yield spec, scan_of(spec, frames, Path(tmp)), None


def rendered_scans(path: Path):
    """(name, scan, (4, 4) its frame to the mesh's) of a mesh scan and its renders as captures."""
    mesh = load_scan(path)
    yield path.name, mesh, np.eye(4)
    placed = place_template(mesh)
    face = face_for(mesh, placed.alignment, placed.registration)
    scene = scene_of(mesh.vertices, mesh.faces)
    for yaw, pitch in POSES:
        view = view_of(face, placed.registration.vertices[4], 450.0, yaw, pitch)
        image, depth = render_view(mesh, view, scene)
        with tempfile.TemporaryDirectory() as tmp:
            write_files(Path(tmp), capture_files(image, np.where(np.isfinite(depth), np.round(depth), 0).astype(np.uint16), CAMERA, 1000.0))
            pose = np.eye(4)
            pose[:3, :3], pose[:3, 3] = view.rotation.T, view.to_scan(np.zeros((1, 3)))[0]
            yield f"yaw {yaw:g} pitch {pitch:g}", load_scan(Path(tmp)), pose


def main() -> None:
    if sys.argv[1:2] == ["--scan"] and len(sys.argv) != 3:
        sys.exit("usage: start_repeatability.py --scan FILE")
    scans = rendered_scans(Path(sys.argv[2])) if sys.argv[1:2] == ["--scan"] else sweep_scans(sys.argv[1:] or DEFAULT)
    bands, reference = {}, None
    for name, scan, pose in scans:
        kept, runs = runs_of(scan)
        a = runs["affine"]
        rmse = 0.0
        if reference is None:
            reference, first = (name, scan, a.vertices[BAND]), a.vertices
        if pose is None:
            pose, rmse = (np.eye(4), 0.0) if name == reference[0] else onto(scan, kabsch(a.vertices, first), reference[1:])
        placed = {run: reg.vertices[BAND] @ pose[:3, :3].T + pose[:3, 3] for run, reg in (runs | {"kept": kept}).items()}
        bands[name] = placed
        first_bands = bands[reference[0]]
        print(f"{name}: morphable share {kept.morphable_share:.2f}, bending x distance {kept.start_product:.3f}, runs' bands "
              f"{np.linalg.norm(placed['affine'] - placed['morphable'], axis=1).mean():.2f} mm apart, from "
              f"{reference[0]}'s: affine {np.linalg.norm(placed['affine'] - first_bands['affine'], axis=1).mean():.2f}, "
              f"morphable {np.linalg.norm(placed['morphable'] - first_bands['morphable'], axis=1).mean():.2f} mm"
              + (f"; fitted onto {reference[0]} to {rmse:.2f} mm rms" if rmse else ""), flush=True)
    for run in ("affine", "morphable", "kept"):
        apart = [np.linalg.norm(bands[x][run] - bands[y][run], axis=1).mean() for x, y in itertools.combinations(bands, 2)]
        print(f"{run}: bands of two scans apart mean {np.mean(apart):.2f}, median {np.median(apart):.2f}, "
              f"max {np.max(apart):.2f} mm over {len(apart)} pairs")


if __name__ == "__main__":
    main()
