"""Rebuild cpapfit/ict/data/ict_face.npz from ../shared/data/ict_face_model/ict_face_model.npz.

The ICT Face Model Light (USC ICT, MIT licence) there holds 100 identity modes and 53 expressions
over 14 388 vertices. The package keeps the neutral face (float32), the first K identity modes
(K: the fewest holding IDENTITY_SHARE of the identity variance over the face area; float16), the
mouth and jaw expressions (float16), the triangles, the 68 landmarks and the index bounds, all
turned rigidly into the template's frame: the rotation and translation that best put the model's
landmarks on the template's (`cpapfit.ict.MULTIPIE_TO_FACEMESH`, no scale).

Usage (needs the project venv and ../shared):
    python tools/build_ict_data.py [--source NPZ]
"""

import argparse
from pathlib import Path

import numpy as np

from cpapfit.similarity import best_rotation
from cpapfit.ict import EXPRESSIONS, MULTIPIE_TO_FACEMESH
from cpapfit.template import load_template

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT.parent / "shared" / "data" / "ict_face_model" / "ict_face_model.npz"
OUT = ROOT / "cpapfit" / "ict" / "data" / "ict_face.npz"
IDENTITY_SHARE = 0.97
MAX_MODES = 60


def modes_needed(identity_mm: np.ndarray, face_vertices: int) -> tuple[int, float]:
    """(K, share): the fewest leading (M, V, 3) mm identity modes whose variance over the face area
    (each mode's squared norm: its weight is N(0, 1)) is at least IDENTITY_SHARE of all M's."""
    variance = np.sum(identity_mm[:, :face_vertices].astype(np.float64) ** 2, axis=(1, 2))
    share = np.cumsum(variance) / variance.sum()
    k = int(np.searchsorted(share, IDENTITY_SHARE) + 1)
    return k, float(share[k - 1])


def to_template(neutral_mm: np.ndarray, landmarks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R (3, 3), t (3,)): the rigid motion x -> R x + t putting the model's landmarks (its (V, 3)
    mm neutral, (68,) vertex indices) best on the template's (least squares, no scale)."""
    pairs = sorted(MULTIPIE_TO_FACEMESH.items())
    src = neutral_mm[landmarks[[k for k, _ in pairs]]].astype(np.float64)
    dst = load_template().vertices[[i for _, i in pairs]]
    rotation = best_rotation(src - src.mean(axis=0), dst - dst.mean(axis=0), np.ones(len(src)))
    return rotation, dst.mean(axis=0) - rotation @ src.mean(axis=0)


def quantised(modes_mm: np.ndarray) -> tuple[np.ndarray, float]:
    """(float16 copy of (M, V, 3) mm modes, its largest rounding error in mm)."""
    half = modes_mm.astype(np.float16)
    return half, float(np.abs(half.astype(np.float64) - modes_mm).max())


def build(source: Path) -> tuple[dict, dict]:
    """(arrays to save, figures to report) of the compact model."""
    src = np.load(source)
    face, head = int(src["face_area_vertices"]), int(src["head_vertices"])
    k, share = modes_needed(src["identity_mm"], face)
    assert k <= MAX_MODES, f"{k} identity modes needed for {IDENTITY_SHARE:.0%} of the variance"
    rotation, translation = to_template(src["neutral_mm"], src["landmarks_multipie68"])
    names = list(src["expression_names"])
    identity, identity_err = quantised(src["identity_mm"][:k].astype(np.float64) @ rotation.T)
    expressions, expression_err = quantised(src["expression_mm"][[names.index(n) for n in EXPRESSIONS]].astype(np.float64) @ rotation.T)
    arrays = {
        "neutral_mm": (src["neutral_mm"].astype(np.float64) @ rotation.T + translation).astype(np.float32),
        "identity_mm": identity, "identity_share": np.float64(share),
        "expression_mm": expressions, "expression_names": np.array(EXPRESSIONS),
        "triangles": src["triangles"].astype(np.int32), "landmarks_multipie68": src["landmarks_multipie68"].astype(np.int32),
        "face_area_vertices": np.int32(face), "head_vertices": np.int32(head),
        "rotation": rotation, "translation_mm": translation,
    }
    figures = {"modes": k, "share": share, "identity_max_error_mm": identity_err, "expression_max_error_mm": expression_err}
    return arrays, figures


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--source", type=Path, default=SOURCE, help="ict_face_model.npz")
    args = ap.parse_args()
    arrays, figures = build(args.source)
    np.savez_compressed(OUT, **arrays)
    print(f"wrote {OUT} ({OUT.stat().st_size / 1e6:.2f} MB): {figures['modes']} identity modes, "
          f"{figures['share']:.2%} of the identity variance over the face area; float16 error "
          f"{figures['identity_max_error_mm']:.4f} mm (identity), {figures['expression_max_error_mm']:.4f} mm (expressions)")


if __name__ == "__main__":
    main()
