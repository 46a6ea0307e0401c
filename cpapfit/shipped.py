"""Data files shipped inside the package (`PACKAGE/data/NAME`), read."""

import io
import json
from importlib import resources

import numpy as np


def npz(package: str, name: str):
    """A shipped .npz file of `package`, read (numpy's NpzFile)."""
    return np.load(io.BytesIO(resources.files(package).joinpath("data", name).read_bytes()))


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """The compressed .npz file of named arrays, as shipped (numpy stamps no date: the same arrays, the same bytes)."""
    out = io.BytesIO()
    np.savez_compressed(out, **arrays)
    return out.getvalue()


def json_data(package: str, name: str):
    """A shipped .json file of `package`, parsed."""
    return json.loads(resources.files(package).joinpath("data", name).read_text())
