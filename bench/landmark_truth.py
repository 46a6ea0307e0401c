"""Detected landmarks against the truth: each subject's lifted landmarks (the alignment's, as every
design finds them) against their true places (mm), one JSON line per subject, then the medians per
kind. ICT subjects (all 100 modes of ../shared's model) as framed captures or turned head meshes,
template-made subjects as captures (any pose). With --single each face is read once, on the image
alone: no reading of the mirror image is taken as the same face (`landmarks.facemesh.SAME_FACE_SHARE`).

Usage: .venv/bin/python bench/landmark_truth.py [--single] capture:9000 mesh:9000 template:0 ...
"""

import argparse
import json
from collections import defaultdict

import numpy as np

import cpapfit.landmarks.facemesh as facemesh
from cpapfit.align.initial import initial_alignment
from cpapfit.template import load_template
from ict_bench import FULL_MODEL
from ict_population import subject
from registration_starts import template_subject


def errors(scan, truth: np.ndarray) -> dict:
    """The alignment's landmarks against the (N, 3) mm true template vertices: mean, median and the
    similarity's inliers' mean distance (mm)."""
    landmarks, _, _ = initial_alignment(scan.seen, load_template())
    e = np.linalg.norm(landmarks.points - truth[landmarks.template_index], axis=1)
    inliers = landmarks.confidence > 0.5
    return {"path": landmarks.path, "count": len(e), "mean_mm": float(e.mean()), "median_mm": float(np.median(e)),
            "inliers_mean_mm": float(e[inliers].mean()) if inliers.any() else None}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--single", action="store_true", help="read each face on the image alone")
    ap.add_argument("subjects", nargs="+", help="kind:seed, kind capture, mesh or template")
    args = ap.parse_args()
    if args.single:
        facemesh.SAME_FACE_SHARE = -1.0
    medians = defaultdict(list)
    for spec in args.subjects:
        kind, seed = spec.split(":")
        scan, truth = template_subject(int(seed)) if kind == "template" else subject(int(seed), kind, FULL_MODEL)[:2]
        row = errors(scan, truth)
        medians[kind].append(row["median_mm"])
        print(json.dumps({"kind": kind, "seed": int(seed), **row}), flush=True)
    for kind, values in medians.items():
        print(f"{kind}: {len(values)} subjects, landmark error median of medians {np.median(values):.2f} mm, mean of medians {np.mean(values):.2f} mm")


if __name__ == "__main__":
    main()
