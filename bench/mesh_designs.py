"""Synthetic subjects as mesh scans in random orientations, designed end to end: each capture's
triangles (with per-vertex colour from its image, or none) turned by `Rotation.random(seed)`, then
`pipeline.design` for both masks. Prints the landmark path, leak, safe window and rim gap, or
the refusal.

Usage: .venv/bin/python bench/mesh_designs.py [--seeds 12]
"""

import argparse
import tempfile
from pathlib import Path

from scipy.spatial.transform import Rotation

from cpapfit.errors import CpapfitError
from cpapfit.io.capture import load_capture
from cpapfit.io.phantom import write_phantom
from cpapfit.phantom import make_phantom
from cpapfit.pipeline import design
from landmarks_alignment import as_mesh


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=12)
    seeds = ap.parse_args().seeds
    print("| seed | mesh | mask | outcome | leak (L/min) | window | rim gap max (mm) |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(seeds):
            write_phantom(make_phantom(seed), Path(tmp) / str(seed))
            capture = load_capture(Path(tmp) / str(seed))
            turn = Rotation.random(random_state=seed).as_matrix()
            for colour in (True, False):
                mesh = as_mesh(capture, turn, colour)
                for mask in ("nasal", "oronasal"):
                    row = f"| {seed} | {'colour' if colour else 'no colour'} | {mask} |"
                    try:
                        d = design(mesh, mask)
                    except CpapfitError as exc:
                        print(f"{row} refused: {exc} | | | |", flush=True)
                        continue
                    fit = d.fits["custom"].summary()
                    print(f"{row} designed ({d.alignment.landmarks.path}) | {fit['leak_l_min']:.2f} | {fit['window_fraction']:.2f} | "
                          f"{d.rim.summary()['rim_gap_max_mm']:.2f} |", flush=True)


if __name__ == "__main__":
    main()
