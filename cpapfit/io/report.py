"""The report files of a design, with what comes from outside the pipeline: the input's SHA-256
and the run date (SOURCE_DATE_EPOCH when set, so that a rebuild gives the same bytes)."""

import datetime
import hashlib
import json
import os
from pathlib import Path

from ..pipeline import Design
from ..report.assemble import Provenance, report_files as assemble_report
from ..scan import Scan
from ..work import at_once


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
    """The pictures and report.html of a design whose files (with fit.json) are `files`, as {name: bytes};
    `submit`: see `assemble.report_files`."""
    provenance = Provenance(scan.source, input_sha256(Path(scan.source)), run_date())
    return assemble_report(d, scan, json.loads(files["fit.json"]), provenance, submit)
