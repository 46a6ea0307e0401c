"""Landmarks and similarity alignment on synthetic subjects.

For each seed: is a face found (and by which path), the mean 3-D error of the lifted landmarks
against the true landmarks, and the similarity-aligned template's mean distance to the true
surface over the mask region (both contact bands). With --render, each capture is first made a
mesh scan (its triangles, with per-vertex colour or none) in a random orientation, so the render
path finds the landmarks.

Usage: .venv/bin/python bench/landmarks_alignment.py [--seeds 100] [--render colour|plain]
"""

import argparse
import platform
import time

import numpy as np
from scipy.spatial.transform import Rotation

from cpapfit.align.initial import initial_alignment
from cpapfit.errors import CpapfitError
from cpapfit.io.capture import load_capture
from cpapfit.io.phantom import write_phantom
from cpapfit.synthetic.accuracy import surface_distance
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.scan import Scan
from cpapfit.template import load_template, mask_region


def as_mesh(capture: Scan, rotation: np.ndarray, colour: bool) -> Scan:
    """A capture's triangles as a mesh scan turned by `rotation` (3, 3), with per-vertex colour or none."""
    colors = None
    if colour:
        colors = np.zeros((len(capture.vertices), 3), dtype=np.uint8)
        colors[capture.pixel_vertex[capture.valid]] = capture.image[capture.valid]
    return Scan(capture.vertices @ rotation.T, capture.faces, capture.normals @ rotation.T, colors=colors)


def one(seed: int, template, region, tmp, render: str | None = None) -> dict:
    ph = make_phantom(seed)
    folder = tmp / f"s{seed}"
    write_phantom(ph, folder)
    scan = load_capture(folder)
    truth = ph.surface
    if render:
        rotation = Rotation.random(random_state=seed).as_matrix()
        scan, truth = as_mesh(scan, rotation, render == "colour"), truth @ rotation.T
    t0 = time.perf_counter()
    try:
        lm, fit, _ = initial_alignment(scan.seen, template)
    except CpapfitError as exc:
        return {"seed": seed, "found": False, "error": str(exc)}
    seconds = time.perf_counter() - t0
    lm_err = np.linalg.norm(lm.points - truth[lm.template_index], axis=1)
    aligned = fit.apply(template.vertices[region])
    dist = surface_distance(aligned, truth, ph.faces)
    return {
        "seed": seed, "found": lm.path == ("render" if render else "image"), "path": lm.path, "landmarks": len(lm.points),
        "lm_err_mean": float(lm_err.mean()), "lm_err_inliers": float(lm_err[lm.confidence > 0.5].mean()),
        "region_mean": float(dist.mean()), "seconds": seconds, "yaw": ph.pose["yaw_deg"], "pitch": ph.pose["pitch_deg"],
    }


def main() -> None:
    import tempfile
    from pathlib import Path

    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--render", choices=("colour", "plain"), help="make each capture a mesh in a random orientation")
    args = ap.parse_args()
    template = load_template()
    region = mask_region(template)
    with tempfile.TemporaryDirectory() as tmp:
        rows = [one(s, template, region, Path(tmp), args.render) for s in range(args.seeds)]
    found = [r for r in rows if r["found"]]
    ok3 = [r for r in found if r["region_mean"] <= 3.0]
    print(f"machine: {platform.machine()}, {platform.python_version()}, seeds 0-{args.seeds - 1}")
    print(f"landmarks found ({'render' if args.render else 'image'} path): {len(found)}/{len(rows)} = {100 * len(found) / len(rows):.1f} %")
    for r in rows:
        if not r["found"]:
            print(f"  seed {r['seed']}: {r.get('path', '')} {r.get('error', '')}")
    for key, label in (("lm_err_mean", "lifted landmark 3-D error, all kept (mm)"),
                       ("lm_err_inliers", "lifted landmark 3-D error, inliers (mm)"),
                       ("region_mean", "aligned template to true surface, mask region mean (mm)"),
                       ("seconds", "landmarks + similarity time (s)")):
        vals = np.array([r[key] for r in found])
        print(f"{label}: mean {vals.mean():.2f}, median {np.median(vals):.2f}, p95 {np.percentile(vals, 95):.2f}, max {vals.max():.2f}")
    print(f"mask-region mean distance <= 3 mm: {len(ok3)}/{len(rows)} = {100 * len(ok3) / len(rows):.1f} %")
    worst = sorted(found, key=lambda r: -r["region_mean"])[:5]
    print("worst:", ", ".join(f"seed {r['seed']} {r['region_mean']:.2f} mm (yaw {r['yaw']:.0f}, pitch {r['pitch']:.0f})" for r in worst))


if __name__ == "__main__":
    main()
