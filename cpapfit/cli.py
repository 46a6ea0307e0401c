"""The command line: parses the arguments and runs the command (`commands.py`, imported only then,
so that `--help` and a bad argument cost no more than Python's start). Nothing else.

Errors the user can cause are printed as one line on stderr with exit code 2, never a traceback; a
bug is one line too, with exit code 3; `cpapfit batch` exits with 1 when some scans failed.
"""

import argparse
import os
import sys
import traceback

from . import __version__
from .errors import CpapfitError

UNITS = ("auto", "mm", "cm", "m", "um", "in")  # what --units takes (`io.units` decides and checks them)
STOCK_HELP = ("the stock cushion to set beside the custom one, fitted as a clinic fits it: best (every size tried; default), "
              "gauge (the size a sizing gauge picks), a size (S, M, L; nasal also W), or none")
EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 3


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
    p.set_defaults(func="cmd_demo")

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
    p.add_argument("--frames", type=int, metavar="N",
                   help="write a sweep of N frames round the face (folders 000/, 001/, ...; ict population) instead of one capture")
    p.set_defaults(func="cmd_phantom")

    scan_help = "mesh file (PLY, OBJ, STL, OFF, GLB), RGB-D capture folder, or a folder of capture folders (a sweep, fused)"
    units_help = "units of a mesh scan: mm, cm, m, um, in (default auto: mm, cm, m or um, decided from the size of the face)"
    p = sub.add_parser("inspect", help="read a scan and say what cpapfit sees in it (units, size, valid depth)")
    p.add_argument("scan", help=scan_help)
    p.add_argument("--units", default="auto", choices=UNITS, help=units_help)
    p.set_defaults(func="cmd_inspect")

    for name, helptext, out_help in (
        ("design", "design the custom cushion and its files", "output folder"),
        ("register", "warp the template onto the scan", "registered_template.ply"),
        ("landmarks", "find the facial landmarks in 3-D and place the template", "landmarks.json"),
        ("evaluate", "evaluate a cushion's fit on a scan", "fit.json"),
    ):
        p = sub.add_parser(name, help=helptext)
        p.add_argument("scan", help=scan_help)
        p.add_argument("--out", required=True, help=out_help)
        p.add_argument("--units", default="auto", choices=UNITS, help=units_help)
        if name in ("design", "register", "landmarks", "evaluate"):
            p.add_argument("--landmarks", help="landmarks JSON overriding detection (scan units)")
        if name == "design":
            p.add_argument("--mask", default="nasal", choices=["nasal", "oronasal"])
            p.add_argument("--stock", default="best", help=STOCK_HELP)
        if name in ("design", "register"):
            add_progress_options(p)
        if name == "evaluate":
            p.add_argument("--cushion", required=True, help="cushion.stl")
            p.add_argument("--generic", action="store_true", help="also evaluate the generic cushion of --mask (the design on the template, placed by the similarity)")
            p.add_argument("--stock", help="also evaluate a stock cushion of --mask fitted as a clinic fits it: a size (S, M, L; nasal also W), "
                                           "gauge (the size a sizing gauge picks) or best (every size tried), at its own headgear force")
            p.add_argument("--mask", choices=["nasal", "oronasal"], help="the cushion for --generic and --stock, the states for --states")
            p.add_argument("--states", action="store_true",
                           help="also press the cushions onto the face asleep: supine with the mouth open, mask pushed by a pillow, CPAP 4 and 20 cmH2O")
            p.add_argument("--force", type=float, help="headgear force in N (default: the force recommended for this cushion; "
                                                       "with --states, raised for them within the awake peak's limit)")
            p.add_argument("--cpap", type=float, default=10.0, help="CPAP pressure in cmH2O (default 10)")
        p.set_defaults(func=f"cmd_{name}")

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
    p.set_defaults(func="cmd_batch")
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
        from . import commands  # here: the stages' imports take a second, --help needs none of them

        return getattr(commands, args.func)(args)
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
