"""The template face: MediaPipe's canonical face, refined, in mm, with the mask contact regions.

Frame: x to the subject's left (image right), y up, z out of the face; millimetres. Vertex
i < 468 of the refined template is MediaPipe Face Mesh landmark i.
"""

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..frozen import freeze_arrays, read_only
from ..shipped import json_data, npz, npz_bytes
from .regions import ContactRegion, contact_region

N_LANDMARKS = 468
SUBDIVISIONS = 3  # Loop subdivision rounds: 468 -> 28 881 vertices
MASKS = ("nasal", "oronasal")
TEMPLATE_TO_CAMERA = np.diag([1.0, -1.0, -1.0])  # a face looking at the camera: y up -> down, z out -> towards it


@dataclass(frozen=True)
class Template:
    """The refined template face.

    vertices: (N, 3) float64 mm; faces: (M, 3) int64; vertex i < N_LANDMARKS is landmark i.
    regions: {"nasal" | "oronasal": ContactRegion}.
    features: {"lips" | "left_eye" | ...: (E, 2) int64 landmark edges} (MediaPipe's connections).
    mirror: (N,) int64, the vertex at each vertex's mirror image across the midline (x = 0).
    """

    vertices: np.ndarray
    faces: np.ndarray
    regions: dict
    features: dict
    mirror: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)

    @property
    def landmarks(self) -> np.ndarray:
        """(468, 3) mm landmark positions on the template."""
        return self.vertices[:N_LANDMARKS]

    def mesh(self) -> trimesh.Trimesh:
        """The template as a trimesh (vertex order kept)."""
        return trimesh.Trimesh(self.vertices, self.faces, process=False)


def _data(name: str) -> dict:
    return json_data(__package__, name)


def canonical_face() -> tuple[np.ndarray, np.ndarray]:
    """MediaPipe's canonical face: (468, 3) float64 vertices in mm and (898, 3) int64 triangles."""
    data = _data("canonical_face.json")
    return np.asarray(data["vertices_cm"], dtype=np.float64) * 10.0, np.asarray(data["faces"], dtype=np.int64)


TEMPLATE_FILE = "template.npz"


@lru_cache(maxsize=1)
def load_template() -> Template:
    """The canonical face refined (~29 000 vertices), with both contact regions, as shipped
    (`template_bytes`, written by tools/build_refined_template.py: `refined_template`, to the bit)."""
    data = npz(__package__, TEMPLATE_FILE)
    regions = {m: ContactRegion(m, data[f"{m}_curve"], data[f"{m}_band"], data[f"{m}_distance"], float(data[f"{m}_half_width_mm"]))
               for m in MASKS}
    features = {k.removeprefix("feature_"): read_only(data[k]) for k in data.files if k.startswith("feature_")}
    return Template(vertices=data["vertices"], faces=data["faces"], regions=regions, features=features, mirror=data["mirror"])


def refined_template() -> Template:
    """The canonical face refined by Loop subdivision (~29 000 vertices), with both contact regions."""
    coarse_v, coarse_f = canonical_face()
    vertices, faces = trimesh.remesh.subdivide_loop(coarse_v, coarse_f, iterations=SUBDIVISIONS)
    vertices, faces = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    marks = _data("contact_regions.json")
    regions = {m: contact_region(m, vertices, faces, marks[m]["anchors"], marks[m]["half_width_mm"]) for m in MASKS}
    features = {k: np.asarray(v, dtype=np.int64) for k, v in _data("canonical_face.json")["features"].items()}
    mirror = cKDTree(vertices).query(vertices * [-1.0, 1.0, 1.0])[1]  # the canonical face is symmetric: exact pairs
    return Template(vertices=vertices, faces=faces, regions=regions, features=features, mirror=mirror)


def template_bytes() -> bytes:
    """The .npz file of `refined_template`, as shipped (it depends on no scan: made once, not at every start)."""
    t = refined_template()
    arrays = {"vertices": t.vertices, "faces": t.faces, "mirror": t.mirror}
    for m, region in t.regions.items():
        arrays |= {f"{m}_curve": region.curve, f"{m}_band": region.band, f"{m}_distance": region.distance,
                   f"{m}_half_width_mm": np.float64(region.half_width_mm)}
    return npz_bytes(arrays | {f"feature_{k}": v for k, v in t.features.items()})


def central_face(template: Template, radius_mm: float = 60.0) -> np.ndarray:
    """(K,) int64 indices of template vertices within radius_mm of the nose tip (landmark 4)."""
    v = template.vertices
    return np.flatnonzero(np.linalg.norm(v - v[4], axis=1) < radius_mm)


def mask_region(template: Template) -> np.ndarray:
    """(K,) sorted template vertex indices of both masks' contact bands."""
    return np.union1d(template.regions["nasal"].band, template.regions["oronasal"].band)
