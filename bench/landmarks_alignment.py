"""Landmarks and similarity alignment on synthetic subjects (issue 3 acceptance figures).

For each seed: is a face found (and by which path), the mean 3-D error of the lifted landmarks
against the true landmarks, and the similarity-aligned template's mean distance to the true
surface over the mask region (both contact bands).

Usage: .venv/bin/python bench/landmarks_alignment.py [--seeds 100]
"""

import argparse
import platform
import time

import numpy as np

from cpapfit.align.initial import initial_alignment
from cpapfit.errors import CpapfitError
from cpapfit.io.capture import load_capture
from cpapfit.io.phantom import write_phantom
from cpapfit.metrics import mask_region, surface_distance
from cpapfit.phantom import make_phantom
from cpapfit.template import load_template


def one(seed: int, template, region, tmp) -> dict:
    ph = make_phantom(seed)
    folder = tmp / f"s{seed}"
    write_phantom(ph, folder)
    scan = load_capture(folder)
    t0 = time.perf_counter()
    try:
        lm, fit, _ = initial_alignment(scan, template)
    except CpapfitError as exc:
        return {"seed": seed, "found": False, "error": str(exc)}
    seconds = time.perf_counter() - t0
    lm_err = np.linalg.norm(lm.points - ph.surface[lm.template_index], axis=1)
    aligned = fit.apply(template.vertices[region])
    dist = surface_distance(aligned, ph.surface, ph.faces)
    return {
        "seed": seed, "found": lm.path == "image", "path": lm.path, "landmarks": len(lm.points),
        "lm_err_mean": float(lm_err.mean()), "lm_err_inliers": float(lm_err[lm.confidence > 0.5].mean()),
        "region_mean": float(dist.mean()), "seconds": seconds, "yaw": ph.pose["yaw_deg"], "pitch": ph.pose["pitch_deg"],
    }


def main() -> None:
    import tempfile
    from pathlib import Path

    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=100)
    args = ap.parse_args()
    template = load_template()
    region = mask_region(template)
    with tempfile.TemporaryDirectory() as tmp:
        rows = [one(s, template, region, Path(tmp)) for s in range(args.seeds)]
    found = [r for r in rows if r["found"]]
    ok3 = [r for r in found if r["region_mean"] <= 3.0]
    print(f"machine: {platform.machine()}, {platform.python_version()}, seeds 0-{args.seeds - 1}")
    print(f"landmarks found (image path): {len(found)}/{len(rows)} = {100 * len(found) / len(rows):.1f} %")
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
