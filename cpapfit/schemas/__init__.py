"""The JSON Schema of each JSON file cpapfit writes (`<name>.schema.json`, draft 2020-12), and the
version every record carries: raised whenever a record's keys or their meaning change."""

import json
from functools import lru_cache
from importlib.resources import files

SCHEMA_VERSION = 3
NAMES = ("fit", "contact_curve", "landmarks", "manifest", "mask")


@lru_cache(maxsize=None)
def schema(name: str) -> dict:
    """The JSON Schema of the record `name` (one of NAMES)."""
    return json.loads(files(__package__).joinpath(f"{name}.schema.json").read_text())
