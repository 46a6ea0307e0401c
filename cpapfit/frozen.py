"""Frozen dataclasses over numpy arrays: the arrays are made read-only too."""

import dataclasses

import numpy as np


def freeze_arrays(obj) -> None:
    """Make every numpy array field of a dataclass instance read-only (call from __post_init__)."""
    for field in dataclasses.fields(obj):
        value = getattr(obj, field.name)
        if isinstance(value, np.ndarray):
            read_only(value)


def read_only(array: np.ndarray) -> np.ndarray:
    """`array`, made read-only (for a cached result shared by its callers)."""
    array.flags.writeable = False
    return array
