"""Data files shipped inside the package (`PACKAGE/data/NAME`), read."""

import io
import json
from importlib import resources

import numpy as np


def npz(package: str, name: str):
    """A shipped .npz file of `package`, read (numpy's NpzFile)."""
    return np.load(io.BytesIO(resources.files(package).joinpath("data", name).read_bytes()))


def json_data(package: str, name: str):
    """A shipped .json file of `package`, parsed."""
    return json.loads(resources.files(package).joinpath("data", name).read_text())
