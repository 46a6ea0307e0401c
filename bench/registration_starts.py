"""What the registration makes of its two elastic ICP runs: both runs (from the affine and from the
morphable start) on subjects with a truth, each run's bending (|L D|^2 from its start), mean pair
distance from the scan and contact bands' mean distance from their true places (mm), and the
registration made of them (one run, or the two blended: `nonrigid.morphable_share`), one JSON line
per subject. ICT subjects (all 100 modes of ../shared's model) as framed captures or head meshes,
template-made subjects as captures (any pose). `--rounds`: the morphable start's ICP rounds at most
(`MorphableParams.iterations`; its default where not given).

Usage: .venv/bin/python bench/registration_starts.py [--rounds N] capture:9001 mesh:9000 template:0 ...
"""

import argparse
import json
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

import cpapfit.align.nonrigid as nr
from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.write import write_files
from cpapfit.pipeline import align, register_template
from cpapfit.synthetic.template_phantom import make_phantom
from cpapfit.template import MASKS, load_template
from ict_bench import FULL_MODEL
from ict_population import subject

BANDS = {mask: load_template().regions[mask].band for mask in MASKS}


def template_subject(seed: int):
    """(scan, truth (N, 3) mm) of template-made subject `seed` as a capture."""
    ph = make_phantom(seed)
    with tempfile.TemporaryDirectory() as tmp:
        write_files(Path(tmp), capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
        return load_scan(Path(tmp)), ph.surface


def runs_of(scan, params: nr.NonrigidParams = nr.NonrigidParams()) -> tuple:
    """The registration `register_template` makes of `scan` (with `params`) and both its elastic runs
    (`Registration`), by start."""
    got = {}
    runs = nr._runs

    def spy(*args, **kwargs):
        done = runs(*args, **kwargs)
        got.update(zip(("affine", "morphable"), (reg for _, reg in done)))
        return done

    nr._runs = spy
    try:
        kept = register_template(scan, align(scan), params)
    finally:
        nr._runs = runs
    return kept, got


def both_runs(scan, truth, params: nr.NonrigidParams = nr.NonrigidParams()) -> dict:
    """Each start's run on `scan` and the registration made of them (its figures, mm; the product and
    the morphable run's share in it), registered with `params`."""
    kept, runs = runs_of(scan, params)
    bands = {name: {m: float(np.linalg.norm(reg.vertices[b] - truth[b], axis=1).mean()) for m, b in BANDS.items()}
             for name, reg in (runs | {"kept": kept}).items()}
    return {name: {"bending": reg.bending, "distance_mm": nr._mean_distance(reg), **bands[name]} for name, reg in runs.items()} | {
        "kept": {"start": kept.start, "product": kept.start_product, "morphable_share": kept.morphable_share, **bands["kept"]}}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("subjects", nargs="+", help="kind:seed, kind capture, mesh or template")
    parser.add_argument("--rounds", type=int, help="the morphable start's ICP rounds at most")
    args = parser.parse_args()
    params = nr.NonrigidParams()
    if args.rounds is not None:
        params = replace(params, morphable=replace(params.morphable, iterations=args.rounds))
    for spec in args.subjects:
        kind, seed = spec.split(":")
        scan, truth = template_subject(int(seed)) if kind == "template" else subject(int(seed), kind, FULL_MODEL)[:2]
        print(json.dumps({"kind": kind, "seed": int(seed), "rounds": params.morphable.iterations, **both_runs(scan, truth, params)}), flush=True)


if __name__ == "__main__":
    main()
