"""The command line: parses arguments, calls the pipeline, reads and writes files. Nothing else.

Errors the user can cause are printed as one line on stderr with exit code 2, never a traceback.
"""

import argparse
import os
import sys
import traceback
from pathlib import Path

import numpy as np

from . import __version__
from .errors import CpapfitError, InputError
from .cushion.nurbs import CushionParams
from .cushion.stock import SIZES
from .evaluate.fit import CUSHIONS, FitParams
from .evaluate.states import fit_states, merged, sleep_states
from .io import load_scan
from .io.cushion import load_cushion
from .io.design import registration_ply
from .io.phantom import write_head_mesh, write_phantom
from .io.summary import counts, summary_csv, summary_html
from .io.units import UNIT_CHOICES
from .io.write import json_bytes, png_bytes, write_bytes, write_files
from .jobs import ScanTask, design_folder, user_landmarks
from .landmarks.types import Landmarks
from .ict.phantom import ict_head_mesh, make_ict_phantom
from .phantom import make_phantom
from .progress import batch_display, stage_display
from .records import evaluate_record, landmarks_file_record
from .pipeline import Alignment, evaluate, evaluated_cushions, face_for, place_template
from .report.pictures import template_regions_picture
from .scan import Scan
from .stock_fit import compared_stock
from .template import load_template

STOCK_HELP = ("the stock cushion to set beside the custom one, fitted as a clinic fits it: best (every size tried; default), "
              "gauge (the size a sizing gauge picks), a size (S, M, L; nasal also W), or none")
EXIT_SOME_FAILED = 1  # cpapfit batch: some scans failed (each is a row of the summary)
EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 1


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
        f"residual median {np.median(res):.2f} mm, p95 {np.percentile(res, 95):.2f} mm (final membrane weight {last.membrane:g})"
    )


def cmd_register(args) -> int:
    scan = load_scan(Path(args.scan), args.units)
    placed = place_template(scan, load_user_landmarks(args, scan))
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
        label = f"stock {fit['stock_fitting']['size']}" if name == "stock" else name
        cv = "n/a" if s["pressure_cv"] is None else f"{s['pressure_cv']:.2f}"
        seal = "does not seal" if s["seal_force_n"] is None else f"seals from {s['seal_force_n']:.1f} N"
        lines.append(
            f"{label} at {s['headgear_force_n']:.1f} N, {fit['cpap_cmh2o']:g} cmH2O: rim pressure mean {s['pressure_mean_kpa']:.2f} kPa, "
            f"CV {cv}, max {s['pressure_max_kpa']:.2f} kPa ({s['pressure_max_mmhg']:.0f} mmHg, {s['pressure_max_region']}), "
            f"{100 * s['window_fraction']:.0f} % in the safe window, leak {s['leak_l_min']:.2f} L/min, {seal}"
        )
    return "; ".join(lines)


def state_summary(row: dict) -> str:
    """One line on a state of fit.json's `states`: each cushion's leak and peak pressure."""
    cells = [f"{name} leak {row[name]['leak_l_min']:.1f} L/min, peak {row[name]['pressure_max_kpa']:.2f} kPa"
             for name in CUSHIONS if name in row]
    cells += [f"not evaluated ({row['error']})"] if "error" in row else []
    return f"{row['name']}: {'; '.join(cells)}"


def asleep_summary(fit: dict, leak_l_min: float = 2.0) -> str:
    """One line on the states of the sleeping face: in how many each cushion leaks over `leak_l_min`, and its worst."""
    states = fit.get("states", [])[1:]
    parts = []
    for name in CUSHIONS:
        rows = [row for row in states if name in row]
        if rows:
            worst = max(rows, key=lambda row: row[name]["leak_l_min"])
            over = sum(row[name]["leak_l_min"] > leak_l_min for row in rows)
            parts.append(f"{name} leaks over {leak_l_min:g} L/min in {over} of {len(rows)} (worst: {worst['name']}, "
                         f"{worst[name]['leak_l_min']:.1f} L/min)")
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
        raise CpapfitError("--generic, --stock and --states need --mask nasal|oronasal: which cushion to compare with, which states to press")
    stock = stock_choice(args.mask, args.stock) if args.stock else None
    if not 0 < args.cpap <= 30:
        raise CpapfitError(f"--cpap {args.cpap:g} cmH2O: CPAP pressures run from about 4 to 20 cmH2O")
    if args.force is not None and not 0 < args.force <= 200:
        raise CpapfitError(f"--force {args.force:g} N: a headgear force is a few to a few tens of newtons")
    scan = load_scan(Path(args.scan), args.units)
    cushion = load_cushion(Path(args.cushion))
    params = FitParams(cpap_cmh2o=args.cpap)
    placed = place_template(scan, load_user_landmarks(args, scan))
    face = face_for(scan, placed.alignment, placed.registration)
    cushions = evaluated_cushions(placed.alignment, cushion, args.mask if args.generic else None)
    fits = evaluate(face, cushions, fit_params=params, force_n=args.force)
    stock = compared_stock(args.mask, face, stock, fit_params=params, asleep=args.states) if stock else None
    fits |= {"stock": stock.best.fit} if stock else {}
    states = None
    if args.states:
        width = CushionParams().flange_mm
        states = fit_states(cushions, face, sleep_states(args.mask), width, fits["custom"].force_n, params, fits)
        if stock:  # the stock cushion at the force the clinic set for it
            states = tuple(map(merged, states, stock.states))
    record = evaluate_record(scan, str(args.cushion), fits, params, stock, states)
    write_bytes(Path(args.out), json_bytes(record))
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
    summaries["export"] = f"{len(run.files)} files in {out / 'design'}: cushion STL and 3MF, mould halves and core (STL), PLY, JSON"
    summaries["evaluate"] = fit_summary(fit)
    summaries["report"] = f"report.html and {sum(name.endswith('.png') for name in run.files)} pictures in {out / 'design'}"
    for stage, summary in summaries.items():  # in the pipeline's order
        print(f"  {stage:<11} {summary}")
    print(report_summary(out / "design", fit))
    return 0


def cmd_phantom(args) -> int:
    if not 0.0 <= args.mouth_open <= 30.0:
        raise InputError(f"--mouth-open {args.mouth_open:g}: give 0-30 mm")
    if args.glasses and args.population != "template":
        raise InputError("--glasses: only the template population wears glasses (--population template)")
    if args.mesh and args.population != "ict":
        raise InputError("--mesh: only the ICT population gives head meshes (--population ict)")
    if args.mesh:
        files = write_head_mesh(ict_head_mesh(args.seed, mouth_open_mm=args.mouth_open), Path(args.out))
    elif args.population == "ict":
        files = write_phantom(make_ict_phantom(args.seed, mouth_open_mm=args.mouth_open), Path(args.out))
    else:
        files = write_phantom(make_phantom(args.seed, mouth_open_mm=args.mouth_open, glasses=args.glasses), Path(args.out))
    kind = "head mesh" if args.mesh else "RGB-D subject"
    opened = f", mouth open {args.mouth_open:g} mm" if args.mouth_open else ""
    worn = ", wearing glasses" if args.glasses else ""
    info(f"wrote synthetic {args.population} {kind} seed {args.seed}{opened}{worn}: {len(files)} files in {args.out}")
    return 0


def cmd_inspect(args) -> int:
    scan = load_scan(Path(args.scan), args.units)
    info(scan.units_note)
    print(f"{args.scan}: {scan_summary(scan)}")
    return 0


def load_user_landmarks(args, scan: Scan):
    """The --landmarks file, in the scan's units, or None."""
    return user_landmarks(getattr(args, "landmarks", None), scan)


def cmd_landmarks(args) -> int:
    """The landmarks and similarity a design would use (detected ones far from the registered face dropped)."""
    scan = load_scan(Path(args.scan), args.units)
    al = place_template(scan, load_user_landmarks(args, scan)).alignment
    write_bytes(Path(args.out), json_bytes(landmarks_file_record(al, scan)))
    info(f"{scan.units_note}; {found_by(al.landmarks)} -> {args.out}")
    return 0


def add_progress_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.add_argument("--verbose", action="store_true", help="print each stage's time")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="cpapfit", description="A personalised CPAP mask cushion from a facial depth scan.")
    ap.add_argument("--version", action="version", version=f"cpapfit {__version__}")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("demo", help="run every built stage on a synthetic subject (no input needed)")
    p.add_argument("--out", default="cpapfit-demo", help="output folder (default: ./cpapfit-demo)")
    p.add_argument("--seed", type=int, default=0, help="synthetic subject seed (default 0)")
    add_progress_options(p)
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("phantom", help="write a synthetic RGB-D subject (or head mesh) with ground truth")
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--out", required=True, help="output folder: the capture (or head.ply) and ground_truth/")
    p.add_argument("--population", default="ict", choices=["ict", "template"],
                   help="ict: a face of the ICT face model (default); template: the template face deformed")
    p.add_argument("--mouth-open", type=float, default=0.0, metavar="MM",
                   help="drop the jaw: the lower lip moves this far, mm (default 0: closed)")
    p.add_argument("--glasses", action="store_true",
                   help="put a glasses frame on the face (seen by the camera, not in the truth; template population)")
    p.add_argument("--mesh", action="store_true", help="write the head as a mesh scan (head.ply, mm) instead of a capture (ict population)")
    p.set_defaults(func=cmd_phantom)

    scan_help = "mesh file (PLY, OBJ, STL, OFF, GLB) or RGB-D capture folder"
    units_help = "units of a mesh scan: mm, cm, m, um, in (default auto: mm, cm, m or um, decided from the size of the face)"
    p = sub.add_parser("inspect", help="read a scan and say what cpapfit sees in it (units, size, valid depth)")
    p.add_argument("scan", help=scan_help)
    p.add_argument("--units", default="auto", choices=UNIT_CHOICES, help=units_help)
    p.set_defaults(func=cmd_inspect)

    for name, helptext, out_help in (
        ("design", "design the custom cushion and its files", "output folder"),
        ("register", "warp the template onto the scan", "registered_template.ply"),
        ("landmarks", "find the facial landmarks in 3-D and place the template", "landmarks.json"),
        ("evaluate", "evaluate a cushion's fit on a scan", "fit.json"),
    ):
        p = sub.add_parser(name, help=helptext)
        p.add_argument("scan", help=scan_help)
        p.add_argument("--out", required=True, help=out_help)
        p.add_argument("--units", default="auto", choices=UNIT_CHOICES, help=units_help)
        if name in ("design", "register", "landmarks", "evaluate"):
            p.add_argument("--landmarks", help="landmarks JSON overriding detection (scan units)")
        if name == "design":
            p.add_argument("--mask", default="nasal", choices=["nasal", "oronasal"])
            p.add_argument("--stock", default="best", help=STOCK_HELP)
            add_progress_options(p)
        if name == "evaluate":
            p.add_argument("--cushion", required=True, help="cushion.stl")
            p.add_argument("--generic", action="store_true", help="also evaluate the generic cushion of --mask (the design on the template, placed by the similarity)")
            p.add_argument("--stock", help="also evaluate a stock cushion of --mask fitted as a clinic fits it: a size (S, M, L; nasal also W), "
                                           "gauge (the size a sizing gauge picks) or best (every size tried), at its own headgear force")
            p.add_argument("--mask", choices=["nasal", "oronasal"], help="the cushion for --generic and --stock, the states for --states")
            p.add_argument("--states", action="store_true",
                           help="also press the cushions onto the face asleep: supine with the mouth open, mask pushed by a pillow, CPAP 4 and 20 cmH2O")
            p.add_argument("--force", type=float, help="headgear force in N (default: the force recommended for this cushion)")
            p.add_argument("--cpap", type=float, default=10.0, help="CPAP pressure in cmH2O (default 10)")
        p.set_defaults(func={"landmarks": cmd_landmarks, "register": cmd_register, "design": cmd_design, "evaluate": cmd_evaluate}[name])

    p = sub.add_parser(
        "batch", help="design every scan in a folder, in parallel (Dask)",
        epilog="exit code: 0 every scan designed or unchanged, 1 some scans failed (rows of the summary), "
               "2 bad arguments or INPUT_DIR (nothing run)",
    )
    p.add_argument("input_dir", help="folder of scans: mesh files and RGB-D capture folders")
    p.add_argument("--out", required=True, help="output folder: one folder per scan, summary.csv, batch_report.html")
    p.add_argument("--mask", default="nasal", choices=["nasal", "oronasal"])
    p.add_argument("--stock", default="best", help=STOCK_HELP)
    p.add_argument("--workers", type=int, help="worker processes of the local cluster (default: one per core)")
    p.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. tcp://10.0.0.5:8786 (default: a local cluster)")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.set_defaults(func=cmd_batch)
    return ap


def one_line(*texts: str) -> str:
    """The texts on one line, whatever their line breaks."""
    return " ".join(" ".join(texts).split())


def notes(exc: BaseException) -> list[str]:
    """What was added to the exception on its way out (e.g. an earlier design removed: `jobs._clearing`)."""
    return getattr(exc, "__notes__", [])


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except CpapfitError as exc:
        print(f"cpapfit: error: {one_line(str(exc), *notes(exc))}", file=sys.stderr)
        return EXIT_USER_ERROR
    except OSError as exc:  # an output path that is a file, a full disk, no permission
        what = f"{exc.filename or ''}: {exc.strerror or exc}"
        print(f"cpapfit: error: {one_line(what, *notes(exc))}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("cpapfit: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug, not the input: still one line, and nothing half-written (writes are atomic)
        if os.environ.get("CPAPFIT_TRACEBACK"):
            traceback.print_exc()
        message = f"{type(exc).__name__}: {one_line(str(exc))[:300]} -- nothing was written for this step; please report it with the scan"
        print(f"cpapfit: internal error: {one_line(message, '(CPAPFIT_TRACEBACK=1 prints the traceback)', *notes(exc))}",
              file=sys.stderr)
        return EXIT_INTERNAL_ERROR


if __name__ == "__main__":
    sys.exit(main())
