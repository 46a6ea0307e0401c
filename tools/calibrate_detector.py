"""Rebuild cpapfit/template/data/detector_offsets.json: where MediaPipe puts each landmark on the
template itself.

The template's landmark i is vertex i of MediaPipe's canonical face, but MediaPipe, run on views
of that very face, places its landmark i a few millimetres away (along the skin, 2.4 mm on
average). The script renders the template's own face (`phantom.NEUTRAL`, no identity change) as
RENDERS synthetic captures in seeded poses, lights and skin tones, detects the landmarks on each
without any offsets, and averages each landmark's offset from its vertex in the template's frame
(undoing each view's similarity). A landmark found with confidence in fewer than half the views
keeps a zero offset. Deterministic: the same poses give the same file.

Usage: .venv/bin/python tools/calibrate_detector.py   (~2 min)
"""

import json
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from cpapfit.io.capture import capture_files, load_capture
from cpapfit.io.write import write_bytes, write_files
from cpapfit.landmarks.detect import detect_landmarks
from cpapfit.phantom import NEUTRAL, make_phantom
from cpapfit.template import N_LANDMARKS, load_template

OUT = Path(__file__).resolve().parents[1] / "cpapfit" / "template" / "data" / "detector_offsets.json"
RENDERS = 60
MIN_CONFIDENCE = 0.5  # as the registration trusts a detected landmark


def offsets_of(seed: int, template, folder: Path) -> tuple[np.ndarray, np.ndarray]:
    """(template indices (K,), offsets (K, 3) mm in the template frame) of one view's confident landmarks."""
    ph = make_phantom(seed, identity=NEUTRAL)
    write_files(folder, capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
    found = detect_landmarks(load_capture(folder), template)
    lm, fit = found.landmarks, found.similarity
    keep = lm.confidence >= MIN_CONFIDENCE
    index = lm.template_index[keep]
    return index, (lm.points[keep] - ph.surface[index]) @ fit.rotation / fit.scale


def main() -> None:
    raw = replace(load_template(), detector_offsets=np.zeros((N_LANDMARKS, 3)))
    total, count = np.zeros((N_LANDMARKS, 3)), np.zeros(N_LANDMARKS)
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(RENDERS):
            index, offsets = offsets_of(seed, raw, Path(tmp) / str(seed))
            np.add.at(total, index, offsets)
            np.add.at(count, index, 1.0)
    found = count >= RENDERS / 2
    mean = np.where(found[:, None], total / np.maximum(count, 1.0)[:, None], 0.0)
    record = {
        "units": "mm", "frame": "template (x to the subject's left, y up, z out of the face)",
        "about": "MediaPipe's landmark i on renders of the template itself, less vertex i (tools/calibrate_detector.py)",
        "renders": RENDERS, "landmarks_calibrated": int(found.sum()),
        "offsets_mm": np.round(mean, 4).tolist(),
    }
    write_bytes(OUT, (json.dumps(record, indent=0) + "\n").encode())
    size = np.linalg.norm(mean[found], axis=1)
    print(f"{OUT}: {found.sum()} of {N_LANDMARKS} landmarks, offset mean {size.mean():.2f} mm, max {size.max():.2f} mm")


if __name__ == "__main__":
    main()
