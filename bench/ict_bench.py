"""What the benches that draw ICT Face Model subjects share: their command-line arguments, and a
head mesh read as `cpapfit` reads a scan file."""

import argparse
import sys
import tempfile
from pathlib import Path

import trimesh

from cpapfit.io import load_scan
from cpapfit.scan import Scan

FULL_MODEL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "ict_face_model" / "ict_face_model.npz"


def ict_arguments(ap: argparse.ArgumentParser, seeds: int = 30, first: int = 8000) -> None:
    """--seeds, --first, --workers, --rows and --model."""
    ap.add_argument("--seeds", type=int, default=seeds)
    ap.add_argument("--first", type=int, default=first)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--rows", type=Path, default=None, help="also write every row here (JSON lines)")
    model_argument(ap)


def model_argument(ap: argparse.ArgumentParser) -> None:
    """--model: the ICT model file the faces are drawn from, or "shipped"."""
    ap.add_argument("--model", default=FULL_MODEL if FULL_MODEL.is_file() else "shipped",
                    help="the ICT model file the faces are drawn from (all its identity modes), or 'shipped' (the package's 40); "
                    f"default {FULL_MODEL} when present")


def model_source(args: argparse.Namespace) -> Path | None:
    """The ICT model file `--model` names (None: the shipped model), said on stderr: the default is the
    shipped model wherever ../shared is not beside this checkout's folder."""
    source = None if str(args.model) == "shipped" else Path(args.model).resolve()
    shipped = "the shipped one" + ("" if FULL_MODEL.is_file() else f" (no {FULL_MODEL})")
    print(f"ICT model: {source or shipped}", file=sys.stderr)
    return source


def scan_of(mesh: trimesh.Trimesh) -> Scan:
    """A mesh written as PLY and read back by `load_scan`, as a scan file is."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "head.ply"
        path.write_bytes(mesh.export(file_type="ply"))
        return load_scan(path)
