"""How repeatable each registration run is on one real face: several scans of the shared mannequin
sweep (../shared/data/truedepth_sweep_mannequin: sub-sweeps fused by `cpapfit`, single frames as
captures), both elastic runs of each (from the affine and from the morphable start,
`registration_starts.runs_of`), every scan fitted rigidly onto the first (the similarity of their
affine runs' vertices, then Open3D's point-to-plane ICP of the scan within 90 mm of the seal bands
onto the first scan), and the runs' seal bands (both masks') compared there: for each run (affine,
morphable, the one kept) the mean distance (mm) between the same template vertices of two scans'
bands, over every pair of scans. No truth: a run that lands in the same place on every scan of a
face is repeatable, not necessarily right.

A scan is "A-B" (frames A to B fused, in that order: B < A runs backwards), "A-B/S" (every S-th)
or "N" (frame N alone, a capture).

Usage: .venv/bin/python bench/start_repeatability.py [SCAN ...]   (default: the scans of RESULTS 2)
"""

import itertools
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
import open3d as o3d

import cpapfit.align.nonrigid as nr
from cpapfit.io import load_scan
from registration_starts import BANDS, runs_of

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


def onto(scan, start: np.ndarray, reference) -> tuple[np.ndarray, float]:
    """(4, 4) transform of `scan` onto the reference scan (Open3D point-to-plane ICP from `start`,
    the scan's points within NEAR_MM of the reference's bands) and the median distance (mm) left."""
    ref_scan, ref_band = reference
    moved = scan.vertices @ start[:3, :3].T + start[:3, 3]
    near = np.linalg.norm(moved - ref_band.mean(axis=0), axis=1) < NEAR_MM
    target = cloud(ref_scan.vertices, ref_scan.normals)
    fit = o3d.pipelines.registration.registration_icp(
        cloud(scan.vertices[near]), target, 3.0, start, o3d.pipelines.registration.TransformationEstimationPointToPlane(),
        o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=60))
    return np.asarray(fit.transformation), fit.inlier_rmse


def main() -> None:
    if not SWEEP.is_dir():
        sys.exit(f"{SWEEP}: not found (the shared data)")
    frames = sorted(p for p in SWEEP.iterdir() if p.is_dir())
    specs = sys.argv[1:] or DEFAULT
    bands, reference = {}, None
    with tempfile.TemporaryDirectory() as tmp:
        for spec in specs:
            scan = scan_of(spec, frames, Path(tmp))
            kept, runs = runs_of(scan)
            a, m = runs["affine"], runs["morphable"]
            ratio = m.bending * nr._mean_distance(m) / (a.bending * nr._mean_distance(a))
            if reference is None:
                pose, rmse, reference, first = np.eye(4), 0.0, (scan, a.vertices[BAND]), a.vertices
            else:
                pose, rmse = onto(scan, kabsch(a.vertices, first), reference)
            placed = {name: reg.vertices[BAND] @ pose[:3, :3].T + pose[:3, 3] for name, reg in runs.items()}
            bands[spec] = placed | {"kept": placed[kept]}
            print(f"{spec}: kept {kept}, bending x distance {ratio:.3f}, runs' bands "
                  f"{np.linalg.norm(placed['affine'] - placed['morphable'], axis=1).mean():.2f} mm apart, "
                  f"fitted onto {specs[0]} to {rmse:.2f} mm rms", flush=True)
    for run in ("affine", "morphable", "kept"):
        apart = [np.linalg.norm(bands[x][run] - bands[y][run], axis=1).mean() for x, y in itertools.combinations(specs, 2)]
        print(f"{run}: bands of two scans apart mean {np.mean(apart):.2f}, median {np.median(apart):.2f}, "
              f"max {np.max(apart):.2f} mm over {len(apart)} pairs")


if __name__ == "__main__":
    main()
