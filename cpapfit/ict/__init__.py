"""The ICT Face Model Light (USC Institute for Creative Technologies, MIT licence): an independent
population of faces, none of them a deformation of the template.

A face is neutral + sum_k w_k identity_k (w_k ~ N(0, 1)) + sum_e a_e expression_e, on the model's
own topology: 14 388 vertices, the face area (0..9408, with the insides of the nostrils and of the
lips), head and neck (9409..11247) and the eyeballs (11248..). The package keeps the first 40 of
the 100 identity modes, 97.0 % of the identity variance over the face area, and the mouth and jaw
expressions, both as float16 (largest rounding error 0.016 mm); `tools/build_ict_data.py` makes
the file. Frame: the template's (x to the subject's left, y up, z out of the face; mm): the model
turned and moved rigidly, no scale, so that its landmarks lie best on the template's.

`random_subject(rng)` draws a face (weights ~ N(0, 1) on every identity mode, the jaw opened as
asked): the synthetic subjects' faces, and the population the stock cushions are sized over.
`load_ict()` is the shipped model; `load_ict(path)` reads the original model file
(`ict_face_model.npz`, as in ../shared/data/ict_face_model/) in full: all 100 identity modes and
the same expressions, float64, turned into the same frame with the shipped rotation and
translation. Subjects drawn from it lie outside the span of the shipped 40 modes, a fair test of
anything that uses those modes as a shape prior.
"""

import zipfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..frozen import freeze_arrays
from ..shipped import npz

LOWER_INNER_LIP = 14  # the template landmark whose drop is a mouth's opening (`jaw_open_weight`, face states)
EXPRESSIONS = (
    "jawOpen", "mouthClose", "jawLeft", "jawRight", "jawForward", "mouthLowerDown_L", "mouthLowerDown_R",
    "mouthFunnel", "mouthStretch_L", "mouthStretch_R",
)
"""The expressions kept (ARKit names), full strength at weight 1 (jawOpen drops the lower lip ~35 mm)."""

MULTIPIE_TO_FACEMESH = {
    27: 168, 30: 4, 31: 98, 32: 97, 33: 2, 34: 326, 35: 327, 36: 33, 39: 133, 42: 362, 45: 263,
    48: 61, 51: 0, 54: 291, 57: 17, 62: 13,
}
"""Multi-PIE / iBUG 68 landmark -> the Face Mesh landmark of the same definition (the template's
vertex): nose bridge and tip, nose base, eye corners, mouth corners, lip mid-points, from the usual
mapping (PeizhiYan/Mediapipe_2_Dlib_Landmarks). Left out where the definitions disagree, their
residual an outlier (`tools/build_template_on_ict.py`): after the similarity fit on the neutral,
8 (chin: the template's lowest point is not the menton) and 29 (mid nose ridge); on the registered
face, 28 (upper nose ridge) and 66 (lower inner lip: the template's lips are apart, the model's
closed)."""

@dataclass(frozen=True)
class IctModel:
    """The compact ICT face model, template frame, mm.

    neutral: (V, 3) float64; identity: (K, V, 3) float64 modes, a face's weights ~ N(0, 1);
    expressions: (E, V, 3) float64 at full strength, named `expression_names` (E,);
    triangles: (T, 3) int64; landmarks: (68,) int64 vertex of each Multi-PIE landmark;
    face_vertices: vertices below it are the face area; head_vertices: those from face_vertices
    to below it are head and neck, the rest the eyeballs.
    identity_share: the share of the full model's identity variance (face area) the K modes hold.
    """

    neutral: np.ndarray
    identity: np.ndarray
    expressions: np.ndarray
    expression_names: tuple[str, ...]
    triangles: np.ndarray
    landmarks: np.ndarray
    face_vertices: int
    head_vertices: int
    identity_share: float

    def __post_init__(self):
        freeze_arrays(self)

    @property
    def face_and_eyes(self) -> np.ndarray:
        """(T',) int64 indices of the triangles of the face area and of the eyeballs (the face as
        a scanner sees it, without head and neck)."""
        t = self.triangles
        return np.flatnonzero((t < self.face_vertices).all(axis=1) | (t >= self.head_vertices).all(axis=1))


FULL_MODEL_KEYS = (
    "neutral_mm", "identity_mm", "expression_mm", "expression_names", "triangles", "landmarks_multipie68",
    "face_area_vertices", "head_vertices",
)
"""The arrays `load_ict(path)` reads from the original model file."""


def load_ict(source: Path | None = None) -> IctModel:
    """The model, template frame: the shipped one (`data/ict_face.npz`) when `source` is None, else
    the original model file at `source` in full (every identity mode, the EXPRESSIONS, float64;
    `identity_share` 1), turned into the template frame with the shipped model's rotation and
    translation. Read once per process and path; InputError if `source` is not that file."""
    return _shipped() if source is None else _full(Path(source).resolve())


@lru_cache(maxsize=1)
def _shipped() -> IctModel:
    with npz(__package__, "ict_face.npz") as data:
        return IctModel(
            neutral=data["neutral_mm"].astype(np.float64), identity=data["identity_mm"].astype(np.float64),
            expressions=data["expression_mm"].astype(np.float64), expression_names=tuple(str(n) for n in data["expression_names"]),
            triangles=data["triangles"].astype(np.int64), landmarks=data["landmarks_multipie68"].astype(np.int64),
            face_vertices=int(data["face_area_vertices"]), head_vertices=int(data["head_vertices"]),
            identity_share=float(data["identity_share"]),
        )


@lru_cache(maxsize=4)
def _full(source: Path) -> IctModel:
    """The original model file at `source` (mm, its own frame) as an IctModel, x -> R x + t with
    the shipped model's R and t."""
    try:
        with np.load(source) as data:
            missing = [key for key in FULL_MODEL_KEYS if key not in data.files]
            if missing:
                raise InputError(f"{source}: not the ICT face model file (no {', '.join(missing)} in it)")
            src = {key: data[key] for key in FULL_MODEL_KEYS}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(f"{source}: cannot read the ICT face model file ({type(exc).__name__}: {exc})".splitlines()[0]) from None
    names = [str(n) for n in src["expression_names"]]
    absent = [name for name in EXPRESSIONS if name not in names]
    shipped = _shipped()
    if absent or src["neutral_mm"].shape != shipped.neutral.shape or src["identity_mm"].shape[1:] != shipped.neutral.shape:
        raise InputError(f"{source}: not the ICT face model file ({', '.join(absent) or 'its vertex count'} differs from the shipped model's)")
    with npz(__package__, "ict_face.npz") as data:
        rotation, translation = data["rotation"], data["translation_mm"]
    return IctModel(
        neutral=src["neutral_mm"].astype(np.float64) @ rotation.T + translation,
        identity=src["identity_mm"].astype(np.float64) @ rotation.T,
        expressions=src["expression_mm"][[names.index(n) for n in EXPRESSIONS]].astype(np.float64) @ rotation.T,
        expression_names=EXPRESSIONS, triangles=src["triangles"].astype(np.int64),
        landmarks=src["landmarks_multipie68"].astype(np.int64), face_vertices=int(src["face_area_vertices"]),
        head_vertices=int(src["head_vertices"]), identity_share=1.0,
    )


def ict_face(model: IctModel, identity_weights: np.ndarray, expression: dict[str, float]) -> np.ndarray:
    """(V, 3) float64 mm vertices of the face with (k,) identity weights (k <= K: the first k
    modes) and {expression name: weight} (template frame)."""
    w = np.asarray(identity_weights, dtype=np.float64)
    face = model.neutral + np.tensordot(w, model.identity[: len(w)], axes=1)
    for name, weight in expression.items():
        face = face + weight * model.expressions[model.expression_names.index(name)]
    return face


def jaw_open_weight(mouth_open_mm: float, model: IctModel | None = None) -> float:
    """The jawOpen weight that moves the lower inner lip's truth point `mouth_open_mm` (the model's
    expressions add to any identity, so this is every face's; `model`: the shipped one if None)."""
    model = load_ict() if model is None else model
    move = template_truth(model.expressions[model.expression_names.index("jawOpen")])[LOWER_INNER_LIP]
    return float(mouth_open_mm / np.linalg.norm(move))


def random_subject(rng: np.random.Generator, mouth_open_mm: float, model: IctModel | None = None) -> tuple[np.ndarray, dict]:
    """((V, 3) mm ICT vertices, template frame; identity record) of a random face of `model` (the
    shipped one if None; weights ~ N(0, 1) on all its identity modes), jaw open as asked."""
    model = load_ict() if model is None else model
    weights = rng.normal(size=len(model.identity))
    expression = {"jawOpen": jaw_open_weight(mouth_open_mm, model)} if mouth_open_mm > 0 else {}
    identity = {"population": "ict", "ict_modes": len(model.identity), "ict_weights": weights.tolist(), "expression": expression}
    if mouth_open_mm > 0:
        identity["mouth_open_mm"] = float(mouth_open_mm)
    return ict_face(model, weights, expression), identity


@lru_cache(maxsize=1)
def template_on_ict() -> tuple[np.ndarray, np.ndarray]:
    """Every template vertex as a point of the ICT topology (`data/template_on_ict.npz`): its (N,)
    int64 ICT triangle and (N, 3) float64 barycentric coordinates there (N = 28 881, the template's
    vertex order): the closest point of the ICT neutral's skin (the eyeball in the eye openings) to
    the template registered onto it (`tools/build_template_on_ict.py`)."""
    with npz(__package__, "template_on_ict.npz") as data:
        triangle, bary = data["triangle"].astype(np.int64), data["bary"].astype(np.float64)
    triangle.flags.writeable = bary.flags.writeable = False
    return triangle, bary


def template_truth(ict_vertices: np.ndarray) -> np.ndarray:
    """(N, 3) float64 mm: where every template vertex is on the ICT face of (V, 3) mm vertices (any
    identity, expression or pose: the same topology), on its triangles exactly."""
    triangle, bary = template_on_ict()
    a, b, c = (np.asarray(ict_vertices, dtype=np.float64)[load_ict().triangles[triangle, k]] for k in range(3))
    return a + bary[:, 1:2] * (b - a) + bary[:, 2:3] * (c - a)
