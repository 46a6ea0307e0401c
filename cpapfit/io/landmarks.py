"""Landmark files: a user's JSON {"points": [[x, y, z], ...], "template_index": [i, ...]} in the
scan's units, and the landmarks cpapfit writes (mm, scan frame, with path and confidence)."""

import json
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..landmarks.mouth import lips_apart_in_points
from ..landmarks.types import Landmarks
from ..scan import Scan
from ..template import load_template
from .units import MM_PER_UNIT
from ..thresholds import MIN_USER_LANDMARKS



def user_landmarks(path: str | Path | None, scan: Scan) -> Landmarks | None:
    """A user landmarks file (in the scan's units) read as `Landmarks` in mm, or None without one."""
    return read_landmarks(Path(path), scan.units, len(load_template().vertices)) if path else None


def read_landmarks(path: Path, units: str, n_template: int) -> Landmarks:
    """A user landmarks file as `Landmarks` in mm (`units`: the scan's unit, e.g. "m")."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such landmarks file")
    try:
        data = json.loads(path.read_text())
        points = np.asarray(data["points"], dtype=np.float64)
        raw_index = np.asarray(data["template_index"])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(f"{path}: not a landmarks file ({type(exc).__name__}: {exc}); expected "
                         '{"points": [[x, y, z], ...], "template_index": [i, ...]}') from None
    if points.ndim != 2 or points.shape[1] != 3 or len(points) != raw_index.size:
        raise InputError(f"{path}: points must be [x, y, z] triples, one per template_index")
    if not np.isfinite(points).all():
        raise InputError(f"{path}: some landmark coordinates are NaN or infinite")
    if raw_index.size and not np.issubdtype(raw_index.dtype, np.integer):
        raise InputError(f"{path}: template_index must be whole numbers (template vertex indices)")
    index = raw_index.astype(np.int64).ravel()
    bad = index[(index < 0) | (index >= n_template)]
    if len(bad):
        raise InputError(f"{path}: template_index {bad[0]} does not exist (the template has {n_template} vertices; Face Mesh landmarks are 0-467)")
    if len(np.unique(index)) != len(index):
        raise InputError(f"{path}: a template_index appears twice")
    if len(index) < MIN_USER_LANDMARKS:
        raise InputError(f"{path}: {len(index)} landmarks; at least {MIN_USER_LANDMARKS} are needed to place the template")
    points = points * MM_PER_UNIT[units]
    return Landmarks(points, index, np.ones(len(index)), "user", f"user landmarks from {path.name}",
                     lips_apart_mm=lips_apart_in_points(points, index))


def landmarks_record(lm: Landmarks) -> dict:
    """The JSON record of landmarks (mm, scan frame)."""
    return {
        "units": "mm", "path": lm.path, "note": lm.note, "rejected": lm.rejected,
        "lips_apart_mm": round(lm.lips_apart_mm, 2) if np.isfinite(lm.lips_apart_mm) else None,
        "points": np.round(lm.points, 4).tolist(),
        "template_index": lm.template_index.tolist(),
        "confidence": np.round(lm.confidence, 4).tolist(),
    }
