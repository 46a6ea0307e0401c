"""The sleeping face: states a cushion designed on the awake face must still seal in.

A mask is worn asleep. Lying on the back, the skin slides (`supine.py`) and the jaw drops (the
lower lip a median 13 mm with oronasal masks, 6 mm with nasal ones); a pillow pushes the mask
sideways and rolls it about its axis; the CPAP pressure runs from 4 to 20 cmH2O. Each `FaceState`
is one such state; `state_face` and `moved` make the face and the cushion of it, so the evaluation
presses a cushion onto every state as onto the awake face, at the awake headgear force (the straps
are set once, awake).

The jaw: the ICT Face Model's `jawOpen` shape (an expression the model adds to any identity),
carried onto the template through the template-ICT correspondence (`cpapfit.ict.template_on_ict`),
smoothed over the template as the morphable basis is, then onto the patient by the linear part of
the map from the template to its registration (the face's size and pose), and scaled so that the
lower inner lip (template landmark 14) moves the state's mouth opening. The supine slide is carried
onto the patient by the same map. The scan moves with the registered template nearest it
(inverse-distance weights of its NEIGHBOURS nearest vertices).
"""

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from ..align.morphable import smooth_fields
from ..frozen import freeze_arrays
from ..normals import lean_mesh
from ..ict import LOWER_INNER_LIP, load_ict, template_truth
from ..template import load_template
from ..errors import InputError
from .fit import CushionFit, Face, FitParams, fit_rim
from .rim import in_plane, refined, rim_in, rim_zone
from .supine import template_supine

NEIGHBOURS = 4
MOUTH_OPEN_MM = {"nasal": 6.0, "oronasal": 13.0}  # the median mouth opening asleep with each mask (3DPiPPIn)
PILLOW_SHIFT_MM, PILLOW_ROLL_DEG = 3.0, 5.0
CPAP_RANGE_CMH2O = (4.0, 20.0)


@dataclass(frozen=True)
class FaceState:
    """One state of the face and mask: `supine` lying on the back (the skin slid, `supine.py`),
    `mouth_open_mm` the lower inner lip's drop (mm), `shift_mm` the mask moved across its axis
    towards the patient's left (negative: right), `roll_deg` turned about its axis (degrees,
    counter-clockwise as seen from in front), `cpap_cmh2o` the pressure (None: the awake evaluation's)."""

    name: str
    supine: bool = False
    mouth_open_mm: float = 0.0
    shift_mm: float = 0.0
    roll_deg: float = 0.0
    cpap_cmh2o: float | None = None

    def parameters(self, awake_cmh2o: float) -> dict:
        """The state's parameters as fit.json records them (`awake_cmh2o`: the awake pressure)."""
        return {"supine": self.supine, "mouth_open_mm": self.mouth_open_mm, "shift_mm": self.shift_mm, "roll_deg": self.roll_deg,
                "cpap_cmh2o": awake_cmh2o if self.cpap_cmh2o is None else self.cpap_cmh2o}


AWAKE = FaceState("awake")


def sleep_states(mask: str) -> tuple[FaceState, ...]:
    """The states a `mask` ("nasal" | "oronasal") cushion is evaluated in besides `AWAKE`: lying on
    the back with the jaw half and fully dropped, the pillow's shift to either side and roll, the
    CPAP range's ends."""
    mouth = MOUTH_OPEN_MM[mask]
    low, high = CPAP_RANGE_CMH2O
    return (
        FaceState(f"supine, mouth open {mouth / 2:g} mm", supine=True, mouth_open_mm=mouth / 2),
        FaceState(f"supine, mouth open {mouth:g} mm", supine=True, mouth_open_mm=mouth),
        FaceState(f"pillow: mask {PILLOW_SHIFT_MM:g} mm to the left", shift_mm=PILLOW_SHIFT_MM),
        FaceState(f"pillow: mask {PILLOW_SHIFT_MM:g} mm to the right", shift_mm=-PILLOW_SHIFT_MM),
        FaceState(f"pillow: mask rolled {PILLOW_ROLL_DEG:g} deg", roll_deg=PILLOW_ROLL_DEG),
        FaceState(f"CPAP {low:g} cmH2O", cpap_cmh2o=low),
        FaceState(f"CPAP {high:g} cmH2O", cpap_cmh2o=high),
    )


@lru_cache(maxsize=1)
def template_jaw() -> np.ndarray:
    """(N, 3) mm: the ICT `jawOpen` shape at full strength carried onto the template (template frame,
    template vertex order), smoothed like the morphable basis."""
    model, template = load_ict(), load_template()
    field = template_truth(model.expressions[model.expression_names.index("jawOpen")])
    out = smooth_fields(field[None], template.vertices, template.faces)[0]
    out.flags.writeable = False
    return out


@dataclass(frozen=True)
class Motions:
    """The face's motions on a registered template (N, 3) mm each, scan frame: `jaw` per mm of mouth
    opening (its lower inner lip moving 1 mm), `supine` the skin's slide lying on the back."""

    jaw: np.ndarray
    supine: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)

    def of(self, state: FaceState) -> np.ndarray:
        """(N, 3) mm: how the registered template moves in `state`."""
        return state.mouth_open_mm * self.jaw + (self.supine if state.supine else 0.0)


def motions(registered: np.ndarray) -> Motions:
    """The `Motions` of a registered template (N, 3) mm: the template's carried onto it by the linear
    part of the map from the template to it."""
    template = load_template().vertices
    linear = np.linalg.lstsq(np.hstack([template, np.ones((len(template), 1))]), registered, rcond=None)[0][:3]
    jaw = template_jaw() @ linear
    return Motions(jaw / np.linalg.norm(jaw[LOWER_INNER_LIP]), template_supine() @ linear)


def state_face(face: Face, move: np.ndarray) -> Face:
    """The `face` with its registered template moved by `move` (N, 3) mm (`Motions.of`) and its scan
    surface with it (each vertex as the template's nearest). The face itself when nothing moves."""
    if not move.any():
        return face
    registered = np.asarray(face.registered.vertices)
    dist, near = cKDTree(registered).query(np.asarray(face.scan.vertices), k=NEIGHBOURS, workers=-1)
    weight = 1.0 / np.maximum(dist, 1e-6)
    scan_move = np.einsum("vk,vkc->vc", weight, move[near]) / weight.sum(axis=1, keepdims=True)
    return replace(face, scan=_moved_surface(face.scan, scan_move),
                   registered=trimesh.Trimesh(registered + move, face.registered.faces, process=False))


def _moved_surface(surface: trimesh.Trimesh | trimesh.PointCloud, move: np.ndarray):
    """A copy of a scan surface with its vertices moved by (V, 3) mm (`normals.lean_mesh`: a state's
    face lives through the design, and a dense scan's cache would be hundreds of MB), sharing the
    surface's table of each vertex's triangles."""
    points = np.asarray(surface.vertices) + move
    if isinstance(surface, trimesh.PointCloud):
        return trimesh.PointCloud(points)
    mesh = lean_mesh(points, np.asarray(surface.faces))
    mesh._cache["vertex_faces"] = surface.vertex_faces  # the same triangles; trimesh's private cache (pinned 4.6.11), as its own setters fill it
    return mesh


def moved(cushion: trimesh.Trimesh, face: Face, shift_mm: float, roll_deg: float) -> trimesh.Trimesh:
    """A copy of a cushion mesh (mm, scan frame) shifted `shift_mm` across the mask axis towards
    the patient's left and rolled `roll_deg` about the axis through the centre of its bounding box
    (the pillow's push; the same centre however finely the mesh is divided); the cushion itself
    when neither."""
    if shift_mm == 0 and roll_deg == 0:
        return cushion
    out = cushion.copy()
    out.apply_transform(_motion(cushion, face, shift_mm, roll_deg))
    return out


def _motion(cushion: trimesh.Trimesh, face: Face, shift_mm: float, roll_deg: float) -> np.ndarray:
    """(4, 4) the rigid motion of `moved`."""
    turn = trimesh.transformations.rotation_matrix(np.radians(roll_deg), face.axis, cushion.bounds.mean(axis=0))
    turn[:3, 3] += shift_mm * in_plane(face.axis, face.up)[0]
    return turn


def state_params(state: FaceState, params: FitParams) -> FitParams:
    """The fit parameters of a state: `params` at the state's CPAP pressure, where it sets one."""
    return params if state.cpap_cmh2o is None else replace(params, cpap_cmh2o=state.cpap_cmh2o)


@dataclass(frozen=True)
class StateFit:
    """The cushions pressed onto one state: `fits` {"custom" | "generic": CushionFit} of those that
    could be, and for any that could not (its rim over too little scanned skin) `error` says why."""

    state: FaceState
    fits: dict[str, CushionFit]
    error: str = ""


def state_faces(face: Face, states: tuple[FaceState, ...]) -> dict[FaceState, Face]:
    """{state: the `face` in it} (`state_face`) for each of `states`: made once, the faces and their
    spatial indexes serve the custom cushion's membrane sizing and its evaluation."""
    motion = motions(np.asarray(face.registered.vertices))
    return {state: state_face(face, motion.of(state)) for state in states}


def fit_states(
    cushions: dict[str, trimesh.Trimesh], face: Face, states: tuple[FaceState, ...], width_mm: float, force_n: float,
    params: FitParams = FitParams(), awake: dict[str, CushionFit] | None = None, thickness: dict[str, np.ndarray] | None = None,
    faces: dict[FaceState, Face] | None = None,
) -> tuple[StateFit, ...]:
    """Every cushion of `cushions` (name -> mesh, mm, scan frame) pressed onto each of `states` of
    `face` at the awake headgear force `force_n` N; `width_mm` the seal flange width. Each cushion is
    refined once, and states that differ only in pressure share their contact lines, those of the
    `awake` fits of the same cushions on this face where given: the numbers are `fit_cushion`'s of
    the moved cushion on the state's face. `thickness`: {name: (V,) mm} of cushions already `refined`;
    `faces`: the face in each state where already made (`state_faces`)."""
    faces = faces or state_faces(face, states)
    thickness = thickness or {}
    fine = {name: (mesh, thickness[name]) if name in thickness else refined(mesh) for name, mesh in cushions.items()}
    turn = max((abs(state.roll_deg) for state in states), default=0.0)
    zones = {name: rim_zone(mesh, face.axis, face.up, t, turn_deg=turn) for name, (mesh, t) in fine.items()}
    rims = {(name, False, 0.0, 0.0, 0.0): fit.rim for name, fit in (awake or {}).items()}
    out = []
    for state in states:
        at = state_params(state, params)
        on = faces[state]
        fits, errors = {}, []
        for name, (mesh, _) in fine.items():
            key = (name, state.supine, state.mouth_open_mm, state.shift_mm, state.roll_deg)
            try:
                if key not in rims:
                    rims[key] = rim_in(zones[name].moved(_motion(mesh, face, state.shift_mm, state.roll_deg)), on.scan, on.registered,
                                       on.axis, on.up)
            except InputError as exc:
                errors.append(f"{name}: {exc}")
                continue
            fits[name] = fit_rim(rims[key], on, width_mm, force_n, at)
        out.append(StateFit(state, fits, "; ".join(errors)))
    return tuple(out)


def merged(a: StateFit, b: StateFit) -> StateFit:
    """One state's fits of two sets of cushions (pressed at their own forces) as one."""
    return replace(a, fits=a.fits | b.fits, error="; ".join(filter(None, (a.error, b.error))))
