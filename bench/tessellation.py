"""One surface, three tessellations: how far the design's figures depend on how finely a scan is
triangulated rather than on the face. ICT heads (`ict_head_mesh`, the full model where
../shared has it) written as PLY at their own tessellation and subdivided (each triangle split,
the surface unchanged) to at most 2.0 and 1.0 mm edges, each designed for a nasal mask with
`pipeline.design` (the stock sizes compared, as `cpapfit design` does). Prints, per head and
tessellation, the registration's error over the mask region against the head's truth, and the
custom and stock cushions' figures awake and at CPAP 20 cmH2O.

Usage: .venv/bin/python bench/tessellation.py [--seeds 8003 8020 8031]
"""

import argparse
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import trimesh

from cpapfit.ict import load_ict
from cpapfit.io import load_scan
from cpapfit.pipeline import design
from cpapfit.synthetic.ict_phantom import ict_head_mesh
from cpapfit.template import load_template, mask_region
from ict_bench import FULL_MODEL

EDGES_MM = (None, 2.0, 1.0)  # None: the head's own tessellation


def designed(seed: int, edge: float | None, folder: str) -> str:
    """One table row: the head of `seed` at `edge` designed, its figures."""
    model = load_ict(FULL_MODEL) if FULL_MODEL.is_file() else load_ict()
    head = ict_head_mesh(seed, model=model)
    vertices, faces = np.asarray(head.mesh.vertices), np.asarray(head.mesh.faces)
    if edge is not None:
        vertices, faces = trimesh.remesh.subdivide_to_size(vertices, faces, edge)
    path = Path(folder) / f"ict{seed}-{edge}.ply"
    trimesh.Trimesh(vertices, faces, process=False).export(path)
    corners = vertices[faces]
    median = float(np.median(np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)))
    d = design(load_scan(path), "nasal")
    region = mask_region(load_template())
    error = float(np.linalg.norm(d.registration.vertices[region] - head.truth[region], axis=1).mean())
    cpap = next(s for s in d.states if s.state.cpap_cmh2o == 20.0)
    awake = {name: fit.summary() for name, fit in d.fits.items()}
    shown = {name: "{leak_l_min:.2f} / {window_fraction:.2f} / {pressure_max_kpa:.2f} / {headgear_force_n:.2f}".format(**a)
             for name, a in awake.items()}
    at_cpap = {name: f"{fit.summary()['leak_l_min']:.1f}" for name, fit in cpap.fits.items()}
    size = d.stock.best.size if d.stock else "none"
    return (f"| {seed} | {median:.2f} ({len(faces)}) | {error:.2f} | {shown['custom']} | {shown.get('stock', '-')} ({size}) | "
            f"{at_cpap['custom']} | {at_cpap.get('stock', '-')} |")

def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[8003, 8020, 8031])
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    print("| head | median edge mm (triangles) | registration error, mask region (mm) | custom awake: leak L/min / window / "
          "peak kPa / force N | stock awake: leak / window / peak / force (size) | custom CPAP 20 leak | stock CPAP 20 leak |")
    print("|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp, ProcessPoolExecutor(args.workers) as pool:
        jobs = [pool.submit(designed, seed, edge, tmp) for seed in args.seeds for edge in EDGES_MM]
        for job in jobs:
            print(job.result(), flush=True)


if __name__ == "__main__":
    main()
