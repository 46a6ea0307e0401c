"""The files of `cpapfit register` and `cpapfit design` (all mm, scan frame), as {name: bytes}:
meshes, records and the report, with what the report takes from outside the pipeline: the input's
SHA-256 and the run date (SOURCE_DATE_EPOCH when set, so that a rebuild gives the same bytes)."""

import datetime
import hashlib
import json
import os
from pathlib import Path

import numpy as np
import trimesh

from .align.nonrigid import Registration
from .fabrication.files import checked_assembly, checked_files
from .io.write import ply_bytes, record_bytes
from .pipeline import Design
from .records import contact_curve_record, design_record, mask_record
from .scan import Scan
from .template import load_template
from .work import at_once


def registration_ply(reg: Registration) -> bytes:
    """The warped template as PLY with residual_mm (-1 where unmatched) and valid vertex properties."""
    residual = np.where(reg.valid, reg.residual, -1.0)
    attributes = {"residual_mm": residual.astype(np.float32), "valid": reg.valid.astype(np.uint8)}
    return ply_bytes(reg.vertices, load_template().faces, attributes)


def design_files(d: Design, scan: Scan) -> dict[str, bytes]:
    """The files of `cpapfit design` (all mm, scan frame), as {name: bytes}: `record_files` and
    `solid_files`, `in_order`."""
    return in_order(record_files(d, scan), solid_files(d.solid, d.mould_parts, d.frame.mesh))


def record_files(d: Design, scan: Scan) -> dict[str, bytes]:
    """The records of a design as {name: bytes}: its registered template, contact curve, mask.json and fit.json."""
    return {
        "registered_template.ply": registration_ply(d.registration),
        "contact_curve.json": record_bytes(contact_curve_record(d)),
        "mask.json": record_bytes(mask_record(d)),
        "fit.json": record_bytes(design_record(d, scan)),
    }


def in_order(records: dict[str, bytes], solids: dict[str, bytes]) -> dict[str, bytes]:
    """A design's `record_files` and `solid_files` as one {name: bytes}, in the order they are listed."""
    first = ("registered_template.ply", "contact_curve.json")
    return {name: records[name] for name in first} | solids | {name: data for name, data in records.items() if name not in first}


def solid_files(cushion: trimesh.Trimesh, mould_parts: dict[str, trimesh.Trimesh], frame: trimesh.Trimesh) -> dict[str, bytes]:
    """The solids' files of a design (the cushion, its mould's parts, the frame, the two assembled;
    mm, scan frame) as {name: bytes}, every STL and 3MF checked as a slicer reads it back
    (`fabrication.files.check_file`: else SolidError, nothing written)."""
    passed = []  # the meshes checked as read back: a file reading back to one of them passes with it
    meshes = checked_files(cushion, "cushion", ("stl", "3mf"), passed)
    for name, part in mould_parts.items():
        meshes |= checked_files(part, name, passed=passed)
    meshes |= checked_files(frame, "frame", passed=passed)
    return meshes | checked_assembly({"cushion": cushion, "frame": frame}, "assembly", passed)


def input_sha256(path: Path) -> str:
    """SHA-256 (hex) of a scan file, or of a capture folder: every file's relative name and bytes, in name order."""
    path = Path(path)
    digest = hashlib.sha256()
    if path.is_file():
        digest.update(path.read_bytes())
        return digest.hexdigest()
    for f in sorted(p for p in path.rglob("*") if p.is_file()):
        digest.update(f.relative_to(path).as_posix().encode() + b"\0")
        digest.update(hashlib.sha256(f.read_bytes()).digest())
    return digest.hexdigest()


def run_date() -> str:
    """The run's UTC date and time as text; from SOURCE_DATE_EPOCH (seconds) when it is set."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    when = datetime.datetime.fromtimestamp(int(epoch), datetime.timezone.utc) if epoch else datetime.datetime.now(datetime.timezone.utc)
    return when.strftime("%Y-%m-%d %H:%M UTC")


def report_files(d: Design, scan: Scan, files: dict[str, bytes], submit=at_once) -> dict[str, bytes]:
    """The pictures and report.html of a design whose files (with fit.json and mask.json) are `files`, as {name: bytes};
    `submit`: see `assemble.report_files`."""
    from .report.assemble import Provenance, report_files as assemble_report  # with matplotlib: here, where it is used

    provenance = Provenance(scan.source, input_sha256(Path(scan.source)), run_date())
    return assemble_report(d, scan, json.loads(files["fit.json"]), json.loads(files["mask.json"]), provenance, submit)
