"""The sleeping face, predicted against the truth: ICT Face Model subjects (drawn from the full model,
`--model`) designed from the closed-mouth head mesh (`ict_head_mesh`, template frame, with its
modelled insides), both masks from one placement, then each state of `sleep_states` evaluated two
ways at the design's headgear force:
- predicted: what the design records (`Design.states`: the jaw carried onto the registered template);
- true: the same cushions pressed onto the ICT face itself in that state, its registered template
  the truth (`HeadMesh.truth`), the mouth opened by the model's own jawOpen (`ict_head_mesh(...,
  mouth_open_mm=)`), or by a second, independent jaw model (`--jaw hinge`: the mandible turned about
  its hinge as the template population's phantoms open it, `cpapfit.synthetic.mouth.open_mouth`, on the
  true template's surface), lying on the back by the measured skin slide (`cpapfit.evaluation.supine`)
  carried onto the true template, the mask moved as the state says.
Also the awake truth, and the mask moved 10 mm sideways on the true face (a cushion that far off must
leak). Per design: every state's leak, window fraction and peak pressure, predicted and true.

With --stock, also the best stock size (`cpapfit.stock_fit`) seated on the true awake face as a clinic
seats it and pressed in every state at its own headgear force.

Usage: .venv/bin/python bench/sleep_states.py [--seeds 30] [--first 8000] [--workers 2] [--jaw ict|hinge]
       [--rows rows.jsonl] [--model NPZ | --model shipped] [--stock]
"""

import argparse
import json
import platform
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import trimesh

from cpapfit import __version__
from cpapfit.errors import CpapfitError, NoStockSeat
from cpapfit.evaluation.fit import face_of, fit_rim
from cpapfit.evaluation.rim import find_rim
from cpapfit.evaluation.states import AWAKE, FaceState, motions, moved, sleep_states, state_face, state_params
from cpapfit.ict import load_ict, random_subject, template_truth
from cpapfit.synthetic.ict_phantom import ict_head_mesh
from cpapfit.synthetic.mouth import open_mouth
from cpapfit.pipeline import design, evaluated_cushions, place_template
from cpapfit.stock_fit import compared_stock, placed_stock
from cpapfit.template import MASKS, load_template
from ict_bench import ict_arguments, model_source, scan_of

FAR = FaceState("mask 10 mm to the left", shift_mm=10.0)
KEYS = ("leak_l_min", "window_fraction", "pressure_max_kpa", "pressure_max_region", "lifted_off")


def head(seed: int, source: Path | None, mouth_open_mm: float, jaw: str):
    """(surface mesh, true registered template (N, 3)) of subject `seed`, mouth open as asked: the
    ICT head mesh opened by the model's jawOpen, or (`jaw` "hinge") the true template's surface with
    the mandible turned about its hinge (`cpapfit.synthetic.mouth.open_mouth`, the template population's jaw)."""
    model = load_ict(source)
    if jaw == "ict":
        h = ict_head_mesh(seed, mouth_open_mm=mouth_open_mm, model=model)
        return h.mesh, h.truth
    template = load_template()
    truth = template_truth(random_subject(np.random.default_rng(seed), 0.0, model)[0])
    if mouth_open_mm > 0:
        truth = open_mouth(truth, template, mouth_open_mm)[0]
    return trimesh.Trimesh(truth, template.faces, process=False), truth


def run(job: tuple[int, Path | None, str, bool]) -> list[dict]:
    """Both masks' designs of subject `seed` and their states, predicted and true."""
    seed, source, jaw, stock = job
    mesh, _ = head(seed, source, 0.0, jaw)
    scan = scan_of(mesh)
    try:
        placed = place_template(scan)
    except CpapfitError as exc:
        return [{"seed": seed, "mask": m, "outcome": "refused", "reason": str(exc)[:200]} for m in MASKS]
    return [_measured(seed, mask, scan, placed, source, jaw, stock) for mask in MASKS]


def _measured(seed: int, mask: str, scan, placed, source, jaw: str, stock: bool) -> dict:
    row = {"seed": seed, "mask": mask}
    t0 = time.perf_counter()
    try:
        d = design(scan, mask, placement=placed)
    except CpapfitError as exc:
        return {**row, "outcome": "refused", "reason": str(exc)[:200]}
    row["design_s"] = time.perf_counter() - t0
    force, width = d.fits["custom"].force_n, d.cushion.params.flange_mm
    pressed = {n: (m, None, force) for n, m in evaluated_cushions(d.alignment, d.solid, mask).items()}  # name -> (mesh, thickness, N)
    predicted = {AWAKE.name: d.fits} | {s.state.name: s.fits for s in d.states}
    faces = {(False, 0.0): face_of(*head(seed, source, 0.0, jaw), d.cushion.axis, d.cushion.up)}
    if stock:  # the best stock size, seated on the true face as a clinic seats it, at its own force
        try:
            fitted = compared_stock(mask, faces[(False, 0.0)], fit_params=d.fit_params, asleep=False).best
        except NoStockSeat as exc:
            row["stock"] = {"not_fitted": str(exc)[:200]}
        else:
            row["stock"] = {"size": fitted.size, **fitted.record()}
            pressed["stock"] = (*placed_stock(mask, fitted, faces[(False, 0.0)]), fitted.fit.force_n)
    states = []
    for state in (AWAKE, *sleep_states(mask), FAR):
        key = (state.supine, state.mouth_open_mm)
        if key not in faces:
            surface, truth = head(seed, source, state.mouth_open_mm, jaw)
            on = face_of(surface, truth, d.cushion.axis, d.cushion.up)
            faces[key] = state_face(on, motions(truth).supine) if state.supine else on
        params = state_params(state, d.fit_params)
        on = faces[key]
        true = {}
        for n, (m, t, f) in pressed.items():  # a compared cushion whose rim is not found here is left out of this state
            try:
                true[n] = fit_rim(find_rim(moved(m, on, state.shift_mm, state.roll_deg), on.scan, on.registered, on.axis, on.up,
                                           thickness=t), on, width, f, params).summary()
            except CpapfitError as exc:
                if n == "custom":
                    return {**row, "outcome": "not evaluated", "reason": f"{state.name}: {exc}"[:200]}
                row.setdefault("left_out", []).append(f"{n} in {state.name}: {exc}"[:200])
        pred = {n: f.summary() for n, f in predicted.get(state.name, {}).items()}
        states.append({"name": state.name, **{f"{kind}_{n}": {k: s[k] for k in KEYS} for kind, by in (("true", true), ("predicted", pred))
                                               for n, s in by.items()}})
    return {**row, "outcome": "made", "force_n": force, "states": states}


def table(rows: list[dict]) -> str:
    """Markdown: per mask and state, over the designs made: the custom cushion's true leak (median,
    share <= 2 L/min), predicted vs true (share within 2 L/min or 30 %, or both lifted off: the
    prediction says the mask comes off and it does; largest difference where not both lifted off),
    peak, window; the generic cushion's true leak."""
    out = ["| mask | state | n | custom true leak median (L/min) | custom <= 2 L/min | predicted within 2 L/min or 30 % (both lifted off) "
           "| largest |pred - true| (L/min) | custom peak median (kPa) | custom window median | generic true leak median | generic <= 2 L/min |",
           "|---" * 11 + "|"]
    for mask in MASKS:
        made = [r for r in rows if r["mask"] == mask and r["outcome"] == "made"]
        if not made:
            continue
        for i, name in enumerate(s["name"] for s in made[0]["states"]):
            got = [r["states"][i] for r in made]
            true = np.array([s["true_custom"]["leak_l_min"] for s in got])
            gen = np.array([s["true_generic"]["leak_l_min"] for s in got if "true_generic" in s])
            pairs = [(s["predicted_custom"], s["true_custom"]) for s in got if "predicted_custom" in s]
            off = [p["lifted_off"] and t["lifted_off"] for p, t in pairs]
            close = [o or abs(p["leak_l_min"] - t["leak_l_min"]) <= max(2.0, 0.3 * t["leak_l_min"]) for o, (p, t) in zip(off, pairs)]
            worst = max((abs(p["leak_l_min"] - t["leak_l_min"]) for o, (p, t) in zip(off, pairs) if not o), default=float("nan"))
            out.append(
                f"| {mask} | {name} | {len(got)} | {np.median(true):.2f} | {100 * np.mean(true <= 2.0):.0f} % "
                f"| {f'{100 * np.mean(close):.0f} % ({sum(off)})' if pairs else '-'} | {worst:.1f} "
                f"| {np.median([s['true_custom']['pressure_max_kpa'] for s in got]):.2f} "
                f"| {100 * np.median([s['true_custom']['window_fraction'] for s in got]):.0f} % "
                f"| {np.median(gen):.2f} | {100 * np.mean(gen <= 2.0):.0f} % |")
    return "\n".join(out)


def stock_tables(rows: list[dict]) -> str:
    """Markdown: custom beside the best stock size, per mask and state (shares of designs at most
    2 L/min and with the peak at most 4.3 kPa, medians), then per subject (in how many of the sleep
    states each seals at most 2 L/min and keeps its peak at most 4.3 kPa). A cushion left out of a
    state (its rim not found there, `left_out`) is out of that state's shares and meets neither
    bound in its subject's counts."""
    made = [r for r in rows if r["outcome"] == "made" and "size" in r.get("stock", {})]  # a stock size seated
    out = ["| mask | state | n | custom <= 2 L/min | custom peak <= 4.3 kPa | stock <= 2 L/min | stock peak <= 4.3 kPa "
           "| custom / stock peak median (kPa) |", "|---" * 8 + "|"]
    for mask in MASKS:
        got = [r for r in made if r["mask"] == mask]
        for i, name in enumerate(s["name"] for s in got[0]["states"] if got):
            on = lambda n: [r["states"][i][f"true_{n}"] for r in got if f"true_{n}" in r["states"][i]]  # noqa: E731 (pressed there)
            share = lambda n, k, lim: 100 * np.mean([s[k] <= lim for s in on(n)])  # noqa: E731
            med = lambda n: np.median([s["pressure_max_kpa"] for s in on(n)])  # noqa: E731
            out.append(f"| {mask} | {name} | {len(got)} | {share('custom', 'leak_l_min', 2.0):.0f} % "
                       f"| {share('custom', 'pressure_max_kpa', 4.3):.0f} % | {share('stock', 'leak_l_min', 2.0):.0f} % "
                       f"| {share('stock', 'pressure_max_kpa', 4.3):.0f} % | {med('custom'):.2f} / {med('stock'):.2f} |")
    out += ["", "| subject | mask | stock size | stock force (N) | custom force (N) | sleep states sealed, custom / stock "
                "| sleep states peak <= 4.3 kPa, custom / stock |", "|---" * 7 + "|"]
    for r in made:
        asleep = r["states"][1:-1]  # the sleep states (not awake, not the mask 10 mm off)
        count = lambda n, k, lim: sum(s[f"true_{n}"][k] <= lim for s in asleep if f"true_{n}" in s)  # noqa: E731
        out.append(f"| {r['seed']} | {r['mask']} | {r['stock']['size']} | {r['stock']['headgear_force_n']:.1f} | {r['force_n']:.1f} "
                   f"| {count('custom', 'leak_l_min', 2.0)} / {count('stock', 'leak_l_min', 2.0)} of {len(asleep)} "
                   f"| {count('custom', 'pressure_max_kpa', 4.3)} / {count('stock', 'pressure_max_kpa', 4.3)} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ict_arguments(ap)
    ap.add_argument("--jaw", default="ict", choices=["ict", "hinge"], help="the true jaw: the ICT model's jawOpen, or the mandible hinged")
    ap.add_argument("--stock", action="store_true", help="also the best stock size fitted as a clinic fits it, at its own force")
    args = ap.parse_args()
    source = model_source(args)
    print(f"cpapfit {__version__}, {platform.machine()}, Python {platform.python_version()}; ICT seeds "
          f"{args.first}-{args.first + args.seeds - 1} ({len(load_ict(source).identity)} identity modes), head meshes, "
          f"true jaw: {args.jaw}; {args.workers} workers")
    rows, t0 = [], time.perf_counter()
    jobs = [(seed, source, args.jaw, args.stock) for seed in range(args.first, args.first + args.seeds)]
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
    if args.stock:
        print()
        print(stock_tables(rows))
    print(f"\ntotal time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
