"""What each command does: read the inputs, call the stages (or `api`), write the outputs, and
say what was done in a line or two on stderr. `cli.py` parses the arguments and imports this
module only when a command runs; what only some commands use (the synthetic subjects, the report
and matplotlib) is imported where it is used, so that `register` and `landmarks` do not wait for it.
"""

import sys
from pathlib import Path

import numpy as np

from . import api
from .cushion.stock import SIZES
from .errors import InputError
from .evaluation.fit import CUSHIONS
from .io import load_scan
from .io.cushion import load_cushion
from .outputs import registration_ply
from .io.landmarks import user_landmarks
from .io.summary import counts, summary_csv, summary_html
from .io.write import json_bytes, png_bytes, record_bytes, write_bytes, write_files
from .jobs import ScanTask, design_folder
from .landmarks.types import Landmarks
from .progress import batch_display, stage_display
from .records import landmarks_file_record
from .pipeline import Alignment, place_template
from .scan import Scan
from .template import load_template

EXIT_SOME_FAILED = 1  # cpapfit batch: some scans failed (each is a row of the summary)


def info(message: str) -> None:
    """A line of progress or decision for the user, on stderr."""
    print(message, file=sys.stderr)


def scan_summary(scan: Scan) -> str:
    """One line describing a loaded scan."""
    kind = (
        f"RGB-D capture {scan.intrinsics.width}x{scan.intrinsics.height}, {int(scan.valid.sum())} valid depth pixels"
        if scan.is_capture else ("point cloud" if scan.is_point_cloud else "mesh")
    )
    size = scan.vertices.max(axis=0) - scan.vertices.min(axis=0)
    return (
        f"{kind}: {len(scan.vertices)} vertices, {len(scan.faces)} triangles, "
        f"{size[0]:.0f} x {size[1]:.0f} x {size[2]:.0f} mm"
    )


def template_summary() -> str:
    """One line describing the template and its contact regions."""
    t = load_template()
    bands = ", ".join(f"{name} band {len(r.band)} vertices" for name, r in t.regions.items())
    return f"{len(t.vertices)} vertices, {len(t.faces)} triangles; {bands}"


def found_by(lm: Landmarks) -> str:
    """How the landmarks were found, and what was rejected first, in words."""
    return f"{len(lm.points)} landmarks by {lm.path}" + (f" ({lm.rejected})" if lm.rejected else "")


def alignment_summaries(al: Alignment) -> dict[str, str]:
    """One line each for the landmarks and similarity stages."""
    lm, fit = al.landmarks, al.similarity
    return {
        "landmarks": f"{found_by(lm)}: {lm.note}",
        "similarity": f"scale {fit.scale:.3f}, landmark RMS {fit.rms_mm:.1f} mm; face check: {al.check.describe()}",
    }


def registration_summary(reg) -> str:
    """One line for the non-rigid stage."""
    last = reg.log[-1]
    res = reg.residual[reg.valid]
    return (
        f"{len(reg.log)} iterations, {int(reg.valid.sum())} of {len(reg.valid)} template vertices matched, "
        f"residual median {np.median(res):.2f} mm, p95 {np.percentile(res, 95):.2f} mm (final membrane weight {last.membrane:g}), "
        + _weights(reg)
    )


def _weights(reg) -> str:
    """How the registration weighs its starts' runs, for `registration_summary`."""
    if reg.other_run is None:
        return f"the {reg.start} start's run"
    share = 100 * reg.morphable_share
    product = f" (product {reg.start_product:.3f})" if np.isfinite(reg.start_product) else ""
    return f"the morphable start's run weighs {share:.0f} %, the affine start's {100 - share:.0f} %{product}"


def cmd_register(args) -> int:
    with stage_display(args.quiet, args.verbose) as on_stage:
        on_stage("reading the scan")
        scan = load_scan(Path(args.scan), args.units)
        placed = place_template(scan, user_landmarks(args.landmarks, scan), on_stage)
    al, reg = placed.alignment, placed.registration
    write_bytes(Path(args.out), registration_ply(reg))
    info(f"{scan.units_note}; {found_by(al.landmarks)}; {registration_summary(reg)} -> {args.out}")
    return 0


def design_summary(fit: dict) -> str:
    """One line on a designed cushion, from its fit.json record."""
    dims, rim = fit["cushion"], fit["fit_before_compression"]
    gap = ("no scan data under the rim" if rim["rim_gap_median_mm"] is None else
           f"median {rim['rim_gap_median_mm']:.2f} mm, max {rim['rim_gap_max_mm']:.2f} mm")
    return (
        f"{fit['mask']} cushion {dims['width_mm']:.0f} wide x {dims['height_mm']:.0f} high x {dims['depth_mm']:.0f} deep mm, "
        f"watertight, thinnest wall {dims['min_wall_mm']:.2f} mm, membrane {dims['membrane_min_mm']:.2f} mm, "
        f"rim-to-skin gap before pre-load {gap}"
    )


def fit_summary(fit: dict) -> str:
    """One line per cushion of a fit.json record: pressure, window, leak at its headgear force."""
    lines = []
    for name in CUSHIONS:
        if name not in fit:
            continue
        s = fit[name]
        label = {"stock": f"stock {fit.get('stock_fitting', {}).get('size')}",
                 "stock_gauge": f"stock {fit.get('stock_fitting', {}).get('gauge_size')} (the gauge's pick)"}.get(name, name)
        cv = "n/a" if s["pressure_cv"] is None else f"{s['pressure_cv']:.2f}"
        seal = "does not seal" if s["seal_force_n"] is None else f"seals from {s['seal_force_n']:.1f} N"
        lines.append(
            f"{label} at {s['headgear_force_n']:.1f} N, {fit['cpap_cmh2o']:g} cmH2O: rim pressure mean {s['pressure_mean_kpa']:.2f} kPa, "
            f"CV {cv}, max {s['pressure_max_kpa']:.2f} kPa ({s['pressure_max_mmhg']:.0f} mmHg, {s['pressure_max_region']}), "
            f"{100 * s['window_fraction']:.0f} % in the safe window, leak {s['leak_l_min']:.2f} L/min, {seal}"
        )
    if "stock_not_fitted" in fit:
        lines.append(f"no stock cushion compared: {fit['stock_not_fitted']}")
    return "; ".join(lines)


def state_summary(row: dict) -> str:
    """One line on a state of fit.json's `states`: each cushion's leak and peak pressure, or that the
    CPAP load lifts it off (its leak figure, the orifice flow of the whole open rim, means nothing)."""
    cells = [f"{name} lifted off by the CPAP load" if row[name].get("lifted_off") else
             f"{name} leak {row[name]['leak_l_min']:.1f} L/min, peak {row[name]['pressure_max_kpa']:.2f} kPa"
             for name in CUSHIONS if name in row]
    cells += [f"not evaluated ({row['error']})"] if "error" in row else []
    return f"{row['name']}: {'; '.join(cells)}"


def asleep_summary(fit: dict, leak_l_min: float = 2.0) -> str:
    """One line on the states of the sleeping face: in how many each cushion leaks over `leak_l_min`
    (a state whose CPAP load lifts it off counts), its worst leak while on the face, and the states
    that lift it off (no leak figure means anything there: the mask is off)."""
    states = fit.get("states", [])[1:]
    parts = []
    for name in CUSHIONS:
        rows = [row for row in states if name in row]
        if not rows:
            continue
        on = [row for row in rows if not row[name].get("lifted_off")]
        off = [row["name"] for row in rows if row[name].get("lifted_off")]
        notes = []
        if on:
            worst = max(on, key=lambda row: row[name]["leak_l_min"])
            notes.append(f"worst on the face: {worst['name']}, {worst[name]['leak_l_min']:.1f} L/min")
        if off:
            notes.append(f"lifted off by the CPAP load: {', '.join(off)}")
        over = sum(row[name]["leak_l_min"] > leak_l_min for row in on) + len(off)
        parts.append(f"{name} leaks over {leak_l_min:g} L/min in {over} of {len(rows)} ({'; '.join(notes)})")
    return f"asleep: {'; '.join(parts)}" if parts else "asleep: not evaluated"


def report_summary(out: Path, fit: dict) -> str:
    """Where the report is and its headline numbers (custom vs stock, awake and asleep)."""
    return f"report: {out / 'report.html'} (open it in a browser)\n  {fit_summary(fit)}\n  {asleep_summary(fit)}"


def stock_choice(mask: str, choice: str) -> str | None:
    """A --stock argument checked against the stock sizes of `mask`: a size, "gauge" or "best"; None for "none"."""
    if choice not in (*SIZES[mask], "gauge", "best", "none"):
        raise InputError(f"--stock {choice}: the {mask} stock sizes are {', '.join(SIZES[mask])}, or gauge, best or none")
    return None if choice == "none" else choice


def cmd_design(args) -> int:
    task = ScanTask(Path(args.scan), Path(args.out), args.mask, args.units, stock_choice(args.mask, args.stock))
    with stage_display(args.quiet, args.verbose) as on_stage:
        run = design_folder(task, args.landmarks, on_stage, parallel=True)
    info(f"{run.units_note}; {design_summary(run.fit)}; {len(run.files)} files in {args.out}")
    for warning in run.fit.get("warnings", []):
        info(f"rescan advised: {warning['message']}")
    info(report_summary(Path(args.out), run.fit))
    return 0


def cmd_evaluate(args) -> int:
    if (args.generic or args.states or args.stock) and not args.mask:
        raise InputError("--generic, --stock and --states need --mask nasal|oronasal: which cushion to compare with, which states to press")
    stock = stock_choice(args.mask, args.stock) if args.stock else None
    if not 0 < args.cpap <= 30:
        raise InputError(f"--cpap {args.cpap:g} cmH2O: CPAP pressures run from about 4 to 20 cmH2O")
    if args.force is not None and not 0 < args.force <= 200:
        raise InputError(f"--force {args.force:g} N: a headgear force is a few to a few tens of newtons")
    scan = load_scan(Path(args.scan), args.units)
    cushion = load_cushion(Path(args.cushion))
    params = api.Params(fit=api.FitParams(cpap_cmh2o=args.cpap))
    record = api.evaluate(scan, cushion, args.mask, args.generic, stock, args.states, args.force, args.landmarks, params, str(args.cushion))
    write_bytes(Path(args.out), record_bytes(record))
    info(f"{scan.units_note}; {fit_summary(record)} -> {args.out}")
    for row in record.get("states", [])[1:]:
        info(f"  {state_summary(row)}")
    return 0


def cmd_batch(args) -> int:
    from .batch import find_scans, run_batch  # here: Dask takes ~1 s to import, other commands need none of it

    out, stock = Path(args.out), stock_choice(args.mask, args.stock)
    if args.workers is not None and (args.workers < 1 or args.scheduler):
        raise InputError("--workers takes a number >= 1, for the local cluster only (with --scheduler the cluster's workers run)")
    scans, others = find_scans(Path(args.input_dir), out)
    if others:
        info(f"not scans, left out: {', '.join(others)}")
    with batch_display(len(scans), args.quiet) as advance:
        rows = run_batch(scans, out, args.mask, args.workers, args.scheduler, lambda row: advance(f"{row.name}: {row.status}"), stock)
    write_files(out, {"summary.csv": summary_csv(rows), "batch_report.html": summary_html(rows, args.mask)})
    for row in rows:
        if row.status == "failed":
            info(f"  {row.name}: {row.error}")
    info(f"{counts(rows)}; outputs, summary.csv and batch_report.html in {out}")
    return EXIT_SOME_FAILED if any(row.status == "failed" for row in rows) else 0


def cmd_demo(args) -> int:
    from .io.phantom import write_phantom
    from .report.pictures import template_regions_picture
    from .synthetic.template_phantom import make_phantom

    out = Path(args.out)
    subject = out / "subject"
    info(f"cpapfit demo: synthetic subject (seed {args.seed}) -> {subject}")
    with stage_display(args.quiet, args.verbose) as on_stage:
        on_stage("synthetic subject")
        write_phantom(make_phantom(args.seed), subject)
        write_bytes(out / "template_regions.png", png_bytes(template_regions_picture(load_template())))
        run = design_folder(ScanTask(subject, out / "design"), on_stage=on_stage, parallel=True)
    d, fit = run.design, run.fit
    summaries = {"scan": scan_summary(load_scan(subject)), "template": template_summary() + f" (picture: {out / 'template_regions.png'})"}
    summaries.update(alignment_summaries(d.alignment))
    summaries["nonrigid"] = registration_summary(d.registration)
    summaries["contact"] = f"seal curve of {len(d.contact.curve)} points, {100 * d.contact.on_scan.mean():.0f} % on the scan"
    summaries["cushion"] = design_summary(fit)
    summaries["export"] = f"{len(run.files)} files in {out / 'design'}: cushion STL and 3MF, mould halves, face plate and core (STL), PLY, JSON"
    summaries["evaluate"] = fit_summary(fit)
    summaries["report"] = f"report.html and {sum(name.endswith('.png') for name in run.files)} pictures in {out / 'design'}"
    for stage, summary in summaries.items():  # in the pipeline's order
        print(f"  {stage:<11} {summary}")
    print(report_summary(out / "design", fit))
    return 0


def cmd_phantom(args) -> int:
    from .io.phantom import write_head_mesh, write_phantom, write_sweep
    from .synthetic.ict_phantom import ict_head_mesh, make_ict_phantom
    from .synthetic.ict_sweep import make_ict_sweep
    from .synthetic.template_phantom import make_phantom

    if not 0.0 <= args.mouth_open <= 30.0:
        raise InputError(f"--mouth-open {args.mouth_open:g}: give 0-30 mm")
    if args.glasses and args.population != "template":
        raise InputError("--glasses: only the template population wears glasses (--population template)")
    if args.mesh and args.population != "ict":
        raise InputError("--mesh: only the ICT population gives head meshes (--population ict)")
    if args.frames is not None and (args.population != "ict" or args.mesh or not 2 <= args.frames <= 200):
        raise InputError(f"--frames {args.frames}: a sweep is 2-200 frames of an ICT subject (--population ict, no --mesh)")
    if args.frames is not None:
        files = write_sweep(make_ict_sweep(args.seed, args.frames, mouth_open_mm=args.mouth_open), Path(args.out))
    elif args.mesh:
        files = write_head_mesh(ict_head_mesh(args.seed, mouth_open_mm=args.mouth_open), Path(args.out))
    elif args.population == "ict":
        files = write_phantom(make_ict_phantom(args.seed, mouth_open_mm=args.mouth_open), Path(args.out))
    else:
        files = write_phantom(make_phantom(args.seed, mouth_open_mm=args.mouth_open, glasses=args.glasses), Path(args.out))
    kind = "head mesh" if args.mesh else (f"sweep of {args.frames} frames" if args.frames else "RGB-D subject")
    opened = f", mouth open {args.mouth_open:g} mm" if args.mouth_open else ""
    worn = ", wearing glasses" if args.glasses else ""
    info(f"wrote synthetic {args.population} {kind} seed {args.seed}{opened}{worn}: {len(files)} files in {args.out}")
    return 0


def cmd_inspect(args) -> int:
    scan = load_scan(Path(args.scan), args.units)
    info(scan.units_note)
    print(f"{args.scan}: {scan_summary(scan)}")
    return 0


def cmd_landmarks(args) -> int:
    """The landmarks and similarity a design would use (detected ones far from the registered face dropped)."""
    scan = load_scan(Path(args.scan), args.units)
    al = place_template(scan, user_landmarks(args.landmarks, scan)).alignment
    write_bytes(Path(args.out), json_bytes(landmarks_file_record(al, scan)))
    info(f"{scan.units_note}; {found_by(al.landmarks)} -> {args.out}")
    return 0
