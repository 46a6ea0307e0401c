"""A JSON file cpapfit wrote, read and validated against the schema the package ships for it; the run date of the tests' designs."""

import json
from pathlib import Path

import jsonschema

from cpapfit.schemas import schema

DATE_EPOCH = "1700000000"  # SOURCE_DATE_EPOCH of the tests' designs: the run date (to the minute) their reports state
BY_FILE = {"fit.json": "fit", "manifest.json": "manifest", "contact_curve.json": "contact_curve", "mask.json": "mask"}


def written(path: Path, name: str | None = None) -> dict:
    """The record in `path`, valid under `cpapfit/schemas/<name>.schema.json` (`name` from the file name if not given)."""
    record = json.loads(Path(path).read_text())
    jsonschema.validate(record, schema(name or BY_FILE[Path(path).name]), format_checker=jsonschema.FormatChecker())
    return record
