"""Non-rigid registration: accuracy on synthetic subjects, speed and memory on a full 640x480
capture, and the error over holes. Against trimesh's nricp_amberg: bench/speed.py.

Usage:
  .venv/bin/python bench/nonrigid.py accuracy [--seeds 50]
  .venv/bin/python bench/nonrigid.py speed
  .venv/bin/python bench/nonrigid.py holes [--seeds 10]
"""

import argparse
import platform
import resource
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from cpapfit.align.correspondences import nearest_on_grid
from cpapfit.align.nonrigid import NonrigidParams, register
from cpapfit.io.capture import capture_files, load_capture
from cpapfit.io.write import write_files
from cpapfit.synthetic import accuracy as truth
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.synthetic.defects import with_holes
from cpapfit.pipeline import align
from cpapfit.template import load_template, mask_region

TEMPLATE = load_template()
REGION = mask_region(TEMPLATE)


def capture(ph, folder: Path, depth=None):
    write_files(folder, capture_files(ph.image, ph.depth_raw if depth is None else depth, ph.intrinsics, ph.sensor.depth_scale))
    return load_capture(folder)


def scan_to_template(scan, vertices):
    """Distances (mm) from scan points over the mask region to the registered template."""
    return truth.scan_to_template(scan.vertices, vertices, TEMPLATE.faces, REGION)


PAPER = NonrigidParams(affine=None, detected_landmark_factor=1.0, coarse_gates=None, symmetry=0)  # the paper's method, no additions


def timed_register(aligned, scan, al, mode, params=NonrigidParams()):
    t0 = time.perf_counter()
    reg = register(aligned, TEMPLATE.faces, scan, al.landmarks, replace(params, correspondence=mode), mirror=TEMPLATE.mirror)
    return reg, time.perf_counter() - t0


def correspondence(vertices, truth, region=REGION):
    """Mean distance (mm) of registered region vertices to their true positions."""
    return float(np.linalg.norm(vertices[region] - truth[region], axis=1).mean())


def subjects(seeds: int, hole_fraction: float = 0.0):
    """(seed, phantom, scan, alignment, similarity-aligned template) for seeds 0..seeds-1, with
    `hole_fraction` of the mask region's depth removed in blobs."""
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seeds):
            ph = make_phantom(seed)
            if hole_fraction:
                ph = with_holes(ph, REGION, hole_fraction, seed)
            scan = capture(ph, Path(tmp) / str(seed))
            al = align(scan)
            yield seed, ph, scan, al, al.similarity.apply(TEMPLATE.vertices)


def accuracy(seeds: int) -> None:
    rows = []
    for _, ph, scan, al, aligned in subjects(seeds):
        grid, t_grid = timed_register(aligned, scan, al, "grid")
        kd, t_kd = timed_register(aligned, scan, al, "kdtree")
        paper, _ = timed_register(aligned, scan, al, "grid", PAPER)
        d = scan_to_template(scan, grid.vertices)
        rows.append({
            "corr": correspondence(grid.vertices, ph.surface),
            "corr_similarity": correspondence(aligned, ph.surface),
            "corr_paper": correspondence(paper.vertices, ph.surface),
            "median": np.median(d), "p95": np.percentile(d, 95), "flipped": truth.flipped_triangles(aligned, grid.vertices, TEMPLATE.faces, REGION),
            "modes": np.linalg.norm(grid.vertices[REGION] - kd.vertices[REGION], axis=1).mean(),
            "t_grid": t_grid, "t_kd": t_kd, "iterations": len(grid.log), "pooled": d,
        })
    print(f"machine: {platform.machine()}, Python {platform.python_version()}, seeds 0-{seeds - 1}")
    for key, label in (
        ("corr_similarity", "correspondence after similarity only, mask-region mean (mm)"),
        ("corr_paper", "correspondence after the paper's non-rigid (no affine start, landmark weight 10) (mm)"),
        ("corr", "correspondence after non-rigid, mask-region mean distance to true position (mm)"),
        ("median", "scan-to-template distance over mask region, median per seed (mm)"),
        ("p95", "scan-to-template distance over mask region, p95 per seed (mm)"),
        ("modes", "grid vs k-d tree registrations, mask-region mean difference (mm)"),
        ("t_grid", "non-rigid time, grid correspondences (s)"),
        ("t_kd", "non-rigid time, k-d tree correspondences (s)"),
        ("iterations", "iterations"),
    ):
        v = np.array([r[key] for r in rows], dtype=float)
        print(f"{label}: mean {v.mean():.3f}, median {np.median(v):.3f}, p95 {np.percentile(v, 95):.3f}, max {v.max():.3f}")
    pooled = np.concatenate([r["pooled"] for r in rows])
    print(f"scan-to-template pooled over all seeds: median {np.median(pooled):.3f} mm, p95 {np.percentile(pooled, 95):.3f} mm")
    print(f"seeds with correspondence <= 1.0 mm: {sum(r['corr'] <= 1.0 for r in rows)}/{len(rows)}")
    print(f"flipped mask-region triangles, all seeds: {sum(r['flipped'] for r in rows)}")


def full_frame(tmp: Path):
    """Seed 0 with a wall behind the head at 900 mm, so ~300 k of the 640x480 pixels are valid."""
    ph = make_phantom(0)
    wall = np.round(np.random.default_rng(0).normal(900.0, 0.5, ph.depth_raw.shape) * ph.sensor.depth_scale / 1000.0)
    return ph, capture(ph, tmp, np.where(ph.depth_raw > 0, ph.depth_raw, wall).astype(np.uint16))


def speed() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        ph, scan = full_frame(Path(tmp))
        al = align(scan)
        aligned = al.similarity.apply(TEMPLATE.vertices)
        print(f"machine: {platform.machine()}, Python {platform.python_version()}; scan {len(scan.vertices)} points, template {len(aligned)} vertices")
        for mode in ("grid", "kdtree"):
            for symmetry, term in ((NonrigidParams().symmetry, "mirror term"), (0.0, "no mirror term")):
                times = []
                for _ in range(3):
                    reg, t = timed_register(aligned, scan, al, mode, NonrigidParams(symmetry=symmetry))
                    times.append(t)
                corr = correspondence(reg.vertices, ph.surface)
                print(f"{mode}, {term}: best of 3 {min(times):.2f} s, median {np.median(times):.2f} s, {len(reg.log)} iterations, "
                      f"correspondence {corr:.3f} mm")
        print(f"peak resident memory of the whole process: {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


def holes(seeds: int) -> None:
    """30 % of the mask region's depth removed in blobs: error of the vertices over the holes."""
    print(f"machine: {platform.machine()}, Python {platform.python_version()}, seeds 0-{seeds - 1}, 30 % of the mask region's depth removed")
    errors = []
    for _, ph, scan, al, aligned in subjects(seeds, 0.3):
        reg, _ = timed_register(aligned, scan, al, "grid")
        matched = nearest_on_grid(scan, ph.surface[REGION]) >= 0  # the true position's pixel holds depth
        errors.append(correspondence(reg.vertices, ph.surface, REGION[~matched]))
        print(f"over the holes: {errors[-1]:.3f} mm; whole region {correspondence(reg.vertices, ph.surface):.3f} mm")
    print(f"mean over seeds {np.mean(errors):.3f} mm, max {np.max(errors):.3f} mm")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("what", choices=["accuracy", "speed", "holes"])
    ap.add_argument("--seeds", type=int, default=None)
    args = ap.parse_args()
    if args.what == "accuracy":
        accuracy(args.seeds or 50)
    elif args.what == "speed":
        speed()
    else:
        holes(args.seeds or 10)


if __name__ == "__main__":
    main()
