"""MediaPipe Face Mesh (0.10.21, static images, refined landmarks) on an RGB image, at 4 rotations.

Landmark i < 468 is canonical-face vertex i; 468-477 are the irises. Each face is read twice, on
the image and on its mirror image (landmark i there read at its mirror partner's place), and the
two readings of landmarks 0-467 averaged: the detector's errors that do not follow the face into
the mirror cancel in part (lifted landmarks nearer their true places on 37 of 50 synthetic faces,
`bench/RESULTS.md` section 1). MediaPipe's C++ logging is kept off the terminal (it writes to file
descriptor 2 directly).
"""

import contextlib
import os
import sys
from functools import lru_cache

import numpy as np

from ..template import N_LANDMARKS, load_template
from ..thresholds import MIN_DETECTION_CONFIDENCE

MAX_FACES = 2  # to notice a second face, not to use it
SAME_FACE_SHARE = 0.1  # a face in the mirror image is the image's face read alike within this share of its size


@contextlib.contextmanager
def quiet_stderr():
    """Silence file descriptor 2 (C++ log lines) for the duration."""
    sys.stderr.flush()
    saved = os.dup(2)
    with open(os.devnull, "wb") as devnull:
        os.dup2(devnull.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)


@lru_cache(maxsize=1)
def _face_mesh():
    os.environ.setdefault("GLOG_minloglevel", "2")
    with quiet_stderr():
        from mediapipe.python.solutions.face_mesh import FaceMesh

        face_mesh = FaceMesh(
            static_image_mode=True, refine_landmarks=True, max_num_faces=MAX_FACES,
            min_detection_confidence=MIN_DETECTION_CONFIDENCE,
        )
    _forget_import_errors("mediapipe")
    return face_mesh


def _forget_import_errors(package: str) -> None:
    """Drop the tracebacks of the errors a `package` keeps in its modules' globals (mediapipe keeps
    the ImportError of its optional audio package): a traceback's frames reach back through the
    import to every caller of the time, whose locals (a scan, its Embree scene, the design) would
    otherwise live as long as the process."""
    for name, module in list(sys.modules.items()):
        if name == package or name.startswith(package + "."):
            for value in list(getattr(module, "__dict__", {}).values()):
                if isinstance(value, BaseException):
                    value.__traceback__ = None


def detect(image: np.ndarray) -> list[np.ndarray]:
    """Faces in an (H, W, 3) uint8 RGB image: a list of (478, 2) pixel coordinates (u, v), centre-based;
    landmarks 0-467 averaged with the mirror image's reading of the same face where it finds one
    (`_averaged`; the irises as read on the image). The mirror image is read only where the image
    shows a face (most of a mesh's axis views and turns show none)."""
    faces = _detect(image)
    if not faces:
        return []
    mirrored = [_unmirrored(face, image.shape[1]) for face in _detect(np.ascontiguousarray(image[:, ::-1]))]
    return [_averaged(face, mirrored) for face in faces]


def _unmirrored(face: np.ndarray, width: int) -> np.ndarray:
    """(468, 2) px landmarks of a face found, as (>= 468, 2) px, in the mirror image of an image `width`
    pixels wide, in the image's pixels: u reflected, landmark i taken from its mirror partner (the
    canonical face is symmetric: `Template.mirror`)."""
    u, v = (width - 1 - face[:N_LANDMARKS, 0]), face[:N_LANDMARKS, 1]
    partner = load_template().mirror[:N_LANDMARKS]
    return np.stack([u, v], axis=1)[partner]


def _averaged(face: np.ndarray, mirrored: list[np.ndarray]) -> np.ndarray:
    """A face's (478, 2) px landmarks, 0-467 averaged with the nearest of the (468, 2) px `mirrored`
    faces' where their landmarks lie a median under SAME_FACE_SHARE of the face's size (its
    landmarks' larger extent) apart: two readings of one face lie a median 0.5-2.4 px apart on
    synthetic captures' 200-300 px faces, up to ~30 px on fran's renders (10 % of its size). A face
    read further apart is not read reliably, and is left as read on the image: averaged, a bare mesh
    painted with a rainbow read 3.3 mm off and passed the face check, which its one reading fails."""
    apart = [float(np.median(np.linalg.norm(face[:N_LANDMARKS] - other, axis=1))) for other in mirrored]
    if not apart or min(apart) > SAME_FACE_SHARE * np.ptp(face[:N_LANDMARKS], axis=0).max():
        return face
    face = face.copy()
    face[:N_LANDMARKS] = 0.5 * (face[:N_LANDMARKS] + mirrored[int(np.argmin(apart))])
    return face


def _detect(image: np.ndarray) -> list[np.ndarray]:
    """MediaPipe's faces in an (H, W, 3) uint8 RGB image, as `detect` gives them, unaveraged."""
    h, w = image.shape[:2]
    with quiet_stderr():
        result = _face_mesh().process(np.ascontiguousarray(image))
    faces = result.multi_face_landmarks or []
    return [np.array([[p.x * w - 0.5, p.y * h - 0.5] for p in face.landmark]) for face in faces]


def unrotate(uv: np.ndarray, k: int, shape: tuple[int, int]) -> np.ndarray:
    """Pixel coordinates found in np.rot90(image, k) mapped back to the (H, W) image's coordinates."""
    shapes = [shape]
    for _ in range(k):
        shapes.append(shapes[-1][::-1])
    for step in range(k, 0, -1):
        w_prev = shapes[step - 1][1]
        uv = np.stack([w_prev - 1 - uv[:, 1], uv[:, 0]], axis=1)
    return uv


def detect_rotations(image: np.ndarray, turns: tuple[int, ...] = (0, 1, 2, 3)) -> list[tuple[int, list[np.ndarray]]]:
    """[(k, faces)] for the image turned by k * 90 degrees, k in `turns`, faces in original pixel coordinates."""
    shape = image.shape[:2]
    return [(k, [unrotate(f, k, shape) for f in detect(np.rot90(image, k))]) for k in turns]
