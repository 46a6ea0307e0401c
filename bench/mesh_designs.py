"""Synthetic subjects as mesh scans or point clouds in random orientations, designed end to end:
each capture's triangles, or its points alone (`--cloud`), with per-vertex colour from its image
or none, turned by `Rotation.random(seed)`, then `pipeline.design` for both masks. Prints the
landmark path, the registration's mean error over the mask region against the subject's true
surface, leak, safe window, rim gap and the quality gates that flag it, or the refusal.

Usage: .venv/bin/python bench/mesh_designs.py [--seeds 12] [--cloud]
"""

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from cpapfit.errors import CpapfitError
from cpapfit.io.capture import load_capture
from cpapfit.io.normals import cloud_normals
from cpapfit.io.phantom import write_phantom
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.pipeline import design
from cpapfit.template import load_template, mask_region
from landmarks_alignment import as_mesh


def as_cloud(mesh):
    """A mesh scan's points alone, their normals estimated as a point cloud's are on reading."""
    return replace(mesh, faces=np.zeros((0, 3), dtype=np.int64), normals=cloud_normals(mesh.vertices))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=12)
    ap.add_argument("--cloud", action="store_true", help="point clouds instead of meshes")
    args = ap.parse_args()
    region = mask_region(load_template())
    kind = "cloud" if args.cloud else "mesh"
    print(f"| seed | {kind} | mask | outcome | error (mm) | leak (L/min) | window | rim gap max (mm) | flagged |")
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seeds):
            ph = make_phantom(seed)
            write_phantom(ph, Path(tmp) / str(seed))
            capture = load_capture(Path(tmp) / str(seed))
            turn = Rotation.random(random_state=seed).as_matrix()
            truth = ph.surface[region] @ turn.T
            for colour in (True, False):
                scan = as_mesh(capture, turn, colour)
                scan = as_cloud(scan) if args.cloud else scan
                for mask in ("nasal", "oronasal"):
                    row = f"| {seed} | {'colour' if colour else 'no colour'} | {mask} |"
                    try:
                        d = design(scan, mask)
                    except CpapfitError as exc:
                        print(f"{row} refused: {exc} | | | | | |", flush=True)
                        continue
                    fit = d.fits["custom"].summary()
                    error = np.linalg.norm(d.registration.vertices[region] - truth, axis=1).mean()
                    print(f"{row} designed ({d.alignment.landmarks.path}) | {error:.2f} | {fit['leak_l_min']:.2f} | "
                          f"{fit['window_fraction']:.2f} | {d.rim.summary()['rim_gap_max_mm']:.2f} | "
                          f"{' '.join(g.code for g in d.quality.flags)} |", flush=True)


if __name__ == "__main__":
    main()
