"""The sleeping face, predicted against the truth: ICT Face Model subjects (drawn from the full model,
`--model`) designed from the closed-mouth head mesh (`ict_head_mesh`, template frame, with its
modelled insides), both masks from one placement, then each state of `sleep_states` evaluated two
ways at the design's headgear force:
- predicted: what the design records (`Design.states`: the jaw carried onto the registered template);
- true: the same cushions pressed onto the ICT face itself in that state, its registered template
  the truth (`HeadMesh.truth`), the mouth opened by the model's own jawOpen (`ict_head_mesh(...,
  mouth_open_mm=)`), or by a second, independent jaw model (`--jaw hinge`: the mandible turned about
  its hinge as the template population's phantoms open it, `cpapfit.phantom.open_mouth`, on the
  true template's surface), lying on the back by the measured skin slide (`cpapfit.evaluate.supine`)
  carried onto the true template, the mask moved as the state says.
Also the awake truth, and the mask moved 10 mm sideways on the true face (a cushion that far off must
leak). Per design: every state's leak, window fraction and peak pressure, predicted and true.

Usage: .venv/bin/python bench/sleep_states.py [--seeds 30] [--first 8000] [--workers 2] [--jaw ict|hinge]
       [--rows rows.jsonl] [--model NPZ | --model shipped]
"""

import argparse
import json
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
import trimesh

from cpapfit import __version__
from cpapfit.errors import CpapfitError
from cpapfit.evaluate.fit import face_of, fit_cushion
from cpapfit.evaluate.states import AWAKE, FaceState, motions, moved, sleep_states, state_face
from cpapfit.ict import load_ict, template_truth
from cpapfit.ict.phantom import ict_head_mesh, random_subject
from cpapfit.phantom import open_mouth
from cpapfit.pipeline import design, evaluated_cushions, place_template
from cpapfit.template import MASKS, load_template
from ict_bench import ict_arguments, model_source, scan_of

FAR = FaceState("mask 10 mm to the left", shift_mm=10.0)
KEYS = ("leak_l_min", "window_fraction", "pressure_max_kpa", "pressure_max_region")


def head(seed: int, source: Path | None, mouth_open_mm: float, jaw: str):
    """(surface mesh, true registered template (N, 3)) of subject `seed`, mouth open as asked: the
    ICT head mesh opened by the model's jawOpen, or (`jaw` "hinge") the true template's surface with
    the mandible turned about its hinge (`cpapfit.phantom.open_mouth`, the template population's jaw)."""
    model = load_ict(source)
    if jaw == "ict":
        h = ict_head_mesh(seed, mouth_open_mm=mouth_open_mm, model=model)
        return h.mesh, h.truth
    template = load_template()
    truth = template_truth(random_subject(np.random.default_rng(seed), 0.0, model)[0])
    if mouth_open_mm > 0:
        truth = open_mouth(truth, template, mouth_open_mm)[0]
    return trimesh.Trimesh(truth, template.faces, process=False), truth


def run(job: tuple[int, Path | None, str]) -> list[dict]:
    """Both masks' designs of subject `seed` and their states, predicted and true."""
    seed, source, jaw = job
    mesh, _ = head(seed, source, 0.0, jaw)
    scan = scan_of(mesh)
    try:
        placed = place_template(scan)
    except CpapfitError as exc:
        return [{"seed": seed, "mask": m, "outcome": "refused", "reason": str(exc)[:200]} for m in MASKS]
    return [_measured(seed, mask, scan, placed, source, jaw) for mask in MASKS]


def _measured(seed: int, mask: str, scan, placed, source, jaw: str) -> dict:
    row = {"seed": seed, "mask": mask}
    t0 = time.perf_counter()
    try:
        d = design(scan, mask, placement=placed)
    except CpapfitError as exc:
        return {**row, "outcome": "refused", "reason": str(exc)[:200]}
    row["design_s"] = time.perf_counter() - t0
    cushions = evaluated_cushions(d.alignment, d.solid, mask)
    force, width = d.fits["custom"].force_n, d.cushion.params.flange_mm
    predicted = {AWAKE.name: d.fits} | {s.state.name: s.fits for s in d.states}
    faces = {}
    states = []
    for state in (AWAKE, *sleep_states(mask), FAR):
        key = (state.supine, state.mouth_open_mm)
        if key not in faces:
            surface, truth = head(seed, source, state.mouth_open_mm, jaw)
            on = face_of(surface, truth, d.cushion.axis, d.cushion.up)
            faces[key] = state_face(on, motions(truth).supine) if state.supine else on
        params = d.fit_params if state.cpap_cmh2o is None else replace(d.fit_params, cpap_cmh2o=state.cpap_cmh2o)
        on = faces[key]
        try:
            true = {n: fit_cushion(moved(m, on, state.shift_mm, state.roll_deg), on, width, force, params).summary()
                    for n, m in cushions.items()}
        except CpapfitError as exc:
            return {**row, "outcome": "not evaluated", "reason": f"{state.name}: {exc}"[:200]}
        pred = {n: f.summary() for n, f in predicted.get(state.name, {}).items()}
        states.append({"name": state.name, **{f"{kind}_{n}": {k: s[k] for k in KEYS} for kind, by in (("true", true), ("predicted", pred))
                                               for n, s in by.items()}})
    return {**row, "outcome": "made", "force_n": force, "states": states}


def table(rows: list[dict]) -> str:
    """Markdown: per mask and state, over the designs made: the custom cushion's true leak (median,
    share <= 2 L/min), predicted vs true (largest difference, share within 2 L/min or 30 %), peak, window;
    the generic cushion's true leak."""
    out = ["| mask | state | n | custom true leak median (L/min) | custom <= 2 L/min | predicted within 2 L/min or 30 % "
           "| largest |pred - true| (L/min) | custom peak median (kPa) | custom window median | generic true leak median | generic <= 2 L/min |",
           "|---" * 11 + "|"]
    for mask in MASKS:
        made = [r for r in rows if r["mask"] == mask and r["outcome"] == "made"]
        if not made:
            continue
        for i, name in enumerate(s["name"] for s in made[0]["states"]):
            got = [r["states"][i] for r in made]
            true = np.array([s["true_custom"]["leak_l_min"] for s in got])
            gen = np.array([s["true_generic"]["leak_l_min"] for s in got])
            pairs = [(s["predicted_custom"]["leak_l_min"], s["true_custom"]["leak_l_min"]) for s in got if "predicted_custom" in s]
            close = [abs(p - t) <= max(2.0, 0.3 * t) for p, t in pairs]
            worst = max((abs(p - t) for p, t in pairs), default=float("nan"))
            out.append(
                f"| {mask} | {name} | {len(got)} | {np.median(true):.2f} | {100 * np.mean(true <= 2.0):.0f} % "
                f"| {f'{100 * np.mean(close):.0f} %' if pairs else '-'} | {worst:.1f} "
                f"| {np.median([s['true_custom']['pressure_max_kpa'] for s in got]):.2f} "
                f"| {100 * np.median([s['true_custom']['window_fraction'] for s in got]):.0f} % "
                f"| {np.median(gen):.2f} | {100 * np.mean(gen <= 2.0):.0f} % |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ict_arguments(ap)
    ap.add_argument("--jaw", default="ict", choices=["ict", "hinge"], help="the true jaw: the ICT model's jawOpen, or the mandible hinged")
    args = ap.parse_args()
    source = model_source(args)
    print(f"cpapfit {__version__}, {platform.machine()}, Python {platform.python_version()}; ICT seeds "
          f"{args.first}-{args.first + args.seeds - 1} ({len(load_ict(source).identity)} identity modes), head meshes, "
          f"true jaw: {args.jaw}; {args.workers} workers")
    rows, t0 = [], time.perf_counter()
    jobs = [(seed, source, args.jaw) for seed in range(args.first, args.first + args.seeds)]
    with ProcessPoolExecutor(args.workers) as pool:
        for done in pool.map(run, jobs):
            for row in done:
                rows.append(row)
                print(" ", row["seed"], row["mask"], row["outcome"], row.get("reason", ""), flush=True)
    if args.rows:
        args.rows.write_text("".join(json.dumps(r) + "\n" for r in rows))
    made = [r for r in rows if r["outcome"] == "made"]
    print(f"\n{len(made)} of {len(rows)} designs made; design time (with its states) median "
          f"{np.median([r['design_s'] for r in made]):.1f} s\n")
    print(table(rows))
    print(f"\ntotal time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
