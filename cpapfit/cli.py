"""The command line: parses arguments, calls the pipeline, reads and writes files. Nothing else.

Errors the user can cause are printed as one line on stderr with exit code 2, never a traceback.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

from . import __version__
from .errors import CpapfitError, NotAvailableError
from .io import load_scan
from .io.landmarks import landmarks_record, read_landmarks
from .io.design import design_files, mask_dimensions, registration_ply
from .io.phantom import write_phantom
from .io.write import json_bytes, png_bytes, write_bytes, write_files
from .phantom import make_phantom
from .progress import stage_display
from .quality import assess_design
from .pipeline import NOT_BUILT_PARTS, Alignment, Design, align, design, missing_stages, register_template, stage_table
from .report.pictures import residual_picture, template_regions_picture
from .scan import Scan
from .template import load_template

EXIT_USER_ERROR = 2


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


def alignment_summaries(al: Alignment) -> dict[str, str]:
    """One line each for the landmarks and similarity stages."""
    lm, fit = al.landmarks, al.similarity
    return {
        "landmarks": f"{len(lm.points)} landmarks by {lm.path} ({lm.note})",
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
    reg = register_template(scan, align(scan, load_user_landmarks(args, scan)))
    write_bytes(Path(args.out), registration_ply(reg))
    info(f"{scan.units_note}; {registration_summary(reg)} -> {args.out}")
    return 0


def design_summary(d: Design) -> str:
    """One line on a designed cushion."""
    dims, rim = mask_dimensions(d), d.rim.summary()
    generic = d.seated["generic"].summary()
    return (
        f"{d.contact.mask} cushion {dims['width_mm']:.0f} wide x {dims['height_mm']:.0f} high x {dims['depth_mm']:.0f} deep mm, "
        f"watertight, thinnest wall {d.checks['min_wall_mm']:.2f} mm, rim-to-skin gap median {rim['rim_gap_median_mm']:.2f} mm, "
        f"max {rim['rim_gap_max_mm']:.2f} mm (generic cushion seated: median {generic['seated_gap_median_mm']:.1f} mm, "
        f"max {generic['seated_gap_max_mm']:.1f} mm)"
    )


def cmd_design(args) -> int:
    with stage_display(args.quiet, args.verbose) as on_stage:
        on_stage("reading the scan")
        scan = load_scan(Path(args.scan), args.units)
        d = design(scan, args.mask, load_user_landmarks(args, scan), on_stage=on_stage)
        on_stage("writing files")
        written = write_files(Path(args.out), design_files(d, scan))
    info(f"{scan.units_note}; {design_summary(d)}; {len(written)} files in {args.out}")
    for flag in assess_design(d, scan).flags:
        info(f"rescan advised: {flag.message}")
    info(f"not built yet: {', '.join(NOT_BUILT_PARTS)}")
    return 0


def cmd_demo(args) -> int:
    out = Path(args.out)
    subject = out / "subject"
    info(f"cpapfit demo: synthetic subject (seed {args.seed}) -> {subject}")
    write_phantom(make_phantom(args.seed), subject)
    scan = load_scan(subject)
    write_bytes(out / "template_regions.png", png_bytes(template_regions_picture(load_template())))
    summaries = {"scan": scan_summary(scan), "template": template_summary() + f" (picture: {out / 'template_regions.png'})"}
    d = design(scan, "nasal")
    summaries.update(alignment_summaries(d.alignment))
    reg = d.registration
    written = write_files(out / "design", design_files(d, scan))
    title = f"synthetic subject {args.seed}: registration residual"
    write_bytes(out / "residual.png", residual_picture(reg.vertices, load_template().faces, reg.residual, d.alignment.similarity, title))
    summaries["nonrigid"] = registration_summary(reg) + f" (picture: {out / 'residual.png'})"
    summaries["contact"] = f"seal curve of {len(d.contact.curve)} points, {100 * d.contact.on_scan.mean():.0f} % on the scan"
    summaries["cushion"] = design_summary(d)
    summaries["export"] = f"{len(written)} files in {out / 'design'}: cushion STL and 3MF, mould halves and core (STL), PLY, JSON"
    for stage in stage_table(summaries):
        print(f"  {stage.name:<11} {'built    ' if stage.built else 'NOT BUILT'}  {stage.summary}")
    print(f"stages not built yet: {', '.join(missing_stages())}; parts not built yet: {', '.join(NOT_BUILT_PARTS)}.")
    return 0


def cmd_phantom(args) -> int:
    files = write_phantom(make_phantom(args.seed), Path(args.out))
    info(f"wrote synthetic subject seed {args.seed}: {len(files)} files in {args.out}")
    return 0


def cmd_inspect(args) -> int:
    scan = load_scan(Path(args.scan), args.units)
    info(scan.units_note)
    print(f"{args.scan}: {scan_summary(scan)}")
    return 0


def load_user_landmarks(args, scan: Scan):
    """The --landmarks file, in the scan's units, or None."""
    path = getattr(args, "landmarks", None)
    return read_landmarks(Path(path), scan.units, len(load_template().vertices)) if path else None


def cmd_landmarks(args) -> int:
    scan = load_scan(Path(args.scan), args.units)
    al = align(scan, load_user_landmarks(args, scan))
    fit = al.similarity
    record = landmarks_record(al.landmarks) | {
        "similarity": {"scale": fit.scale, "rotation": fit.rotation.tolist(), "translation_mm": fit.translation.tolist(),
                       "landmark_rms_mm": fit.rms_mm, "note": "template (mm) -> scan (mm): x -> scale * R x + t"},
        "face_check": {"coverage": al.check.coverage, "median_gap_mm": al.check.median_gap_mm, "nose_above_sides_mm": al.check.ridge_mm,
                       "nose_above_lip_mm": al.check.below_mm},
        "source": str(args.scan), "scan_units": scan.units,
    }
    write_bytes(Path(args.out), json_bytes(record))
    info(f"{scan.units_note}; {len(al.landmarks.points)} landmarks by {al.landmarks.path} -> {args.out}")
    return 0


def not_available(command: str):
    """A command handler for a stage not built yet: reads the scan, then says so plainly."""

    def handler(args) -> int:
        if getattr(args, "scan", None):
            load_scan(Path(args.scan), getattr(args, "units", "auto"))  # bad input is still reported as such
        raise NotAvailableError(
            f"cpapfit {command}: not available yet (stages not built: {', '.join(missing_stages())}); no output written"
        )

    return handler


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="cpapfit", description="A personalised CPAP mask cushion from a facial depth scan.")
    ap.add_argument("--version", action="version", version=f"cpapfit {__version__}")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("demo", help="run every built stage on a synthetic subject (no input needed)")
    p.add_argument("--out", default="cpapfit-demo", help="output folder (default: ./cpapfit-demo)")
    p.add_argument("--seed", type=int, default=0, help="synthetic subject seed (default 0)")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("phantom", help="write a synthetic RGB-D subject with ground truth")
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--out", required=True, help="output capture folder")
    p.set_defaults(func=cmd_phantom)

    scan_help = "mesh file (PLY, OBJ, STL, OFF, GLB) or RGB-D capture folder"
    units_help = "units of a mesh scan (default auto: decided from the size of the face)"
    p = sub.add_parser("inspect", help="read a scan and say what cpapfit sees in it (units, size, valid depth)")
    p.add_argument("scan", help=scan_help)
    p.add_argument("--units", default="auto", choices=["auto", "mm", "cm", "m"], help=units_help)
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
        p.add_argument("--units", default="auto", choices=["auto", "mm", "cm", "m"], help=units_help)
        if name in ("design", "register", "landmarks"):
            p.add_argument("--landmarks", help="landmarks JSON overriding detection (scan units)")
        if name == "design":
            p.add_argument("--mask", default="nasal", choices=["nasal", "oronasal"])
            p.add_argument("--quiet", action="store_true", help="no progress display")
            p.add_argument("--verbose", action="store_true", help="print each stage's time")
        if name == "evaluate":
            p.add_argument("--cushion", required=True, help="cushion.stl")
            p.add_argument("--generic", action="store_true", help="also evaluate the generic cushion")
        p.set_defaults(func={"landmarks": cmd_landmarks, "register": cmd_register, "design": cmd_design}.get(name, not_available(name)))

    p = sub.add_parser("batch", help="run design on every scan in a folder (Dask)")
    p.add_argument("input_dir")
    p.add_argument("--out", required=True)
    p.add_argument("--scheduler", help="address of an existing Dask scheduler")
    p.set_defaults(func=not_available("batch"))
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except CpapfitError as exc:
        print(f"cpapfit: error: {' '.join(str(exc).split())}", file=sys.stderr)  # one line, whatever the message
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("cpapfit: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
