"""The stages strung together. Each stage is a pure function; this module only sequences them."""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Callable

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from .align.check import FaceCheck
from .align.initial import initial_alignment, landmark_free_alignment
from .align.morphable import ShapeBasis, ict_basis
from .align.nonrigid import NonrigidParams, Registration, register
from .clustering import thinned
from .crop import mesh_scan_near
from .cushion.contact import Contact, transfer_contact
from .cushion.nurbs import Cushion, CushionParams, design_cushion
from .cushion.solid import cushion_sheet, membrane_sheet
from .cushion.generic import NOSE_TIP, place, template_cushion
from .cushion.compensation import Preload, compensated_cushion
from .cushion.envelope import enveloped_cushion, headgear_force
from .evaluation.fit import CushionFit, Face, FitParams, at_force, face_of, fit_cushion
from .evaluation.gap import RimGap, rim_gap
from .evaluation.rim import require_dense
from .evaluation.states import FaceState, StateFit, fit_states, sleep_states, state_faces, state_params
from .errors import NoStockSeat
from .fabrication.dead_space import dead_space_ml, ring_clearance
from .fabrication.files import SolidError, check_closed, check_solid, written_clean
from .fabrication.frame import Frame, build_frame
from .fabrication.mould import Mould, mould
from .quality.proportions import proportions
from .quality.gates import Quality, assess, require_quality
from .thresholds import QualityParams
from .similarity import Similarity
from .solids import self_intersecting_edges
from .landmarks.noise import LandmarkNoise
from .landmarks.types import Landmarks
from .scan import SEEN_CUBE_MM, Scan, scan_surface
from .stock_fit import StockComparison, fitting_stock, stock_solids
from .template import load_template, mask_region
from .work import ahead, at_once

SURFACE_REACH_MM = 30.0  # the scan kept for pressing cushions: this near the seal bands, for any size, pushed or rolled


@dataclass(frozen=True)
class Alignment:
    """The template placed on a scan: landmarks, similarity (template -> scan, mm) and the face check."""

    landmarks: Landmarks
    similarity: Similarity
    check: FaceCheck


def align(scan: Scan, user_landmarks: Landmarks | None = None, landmark_noise: LandmarkNoise = LandmarkNoise()) -> Alignment:
    """Stages landmarks and similarity on a scan (`landmark_noise` on detected landmarks: none by
    default), as it is seen (`Scan.seen`)."""
    return Alignment(*initial_alignment(scan.seen, load_template(), user_landmarks, landmark_noise))


def register_template(scan: Scan, alignment: Alignment, params: NonrigidParams = NonrigidParams()) -> Registration:
    """Stage nonrigid: the similarity-aligned template warped onto the scan (a fused sweep's face:
    `registered_part`)."""
    template = load_template()
    basis = template_basis(params.morphable.modes) if params.morphable else None
    aligned = alignment.similarity.apply(template.vertices)
    return register(aligned, template.faces, registered_part(scan, aligned, alignment.similarity.scale, params), alignment.landmarks,
                    params, template.mirror, basis)


def registered_part(scan: Scan, aligned: np.ndarray, scale: float, params: NonrigidParams = NonrigidParams()) -> Scan:
    """The part of a scan the template is registered on: a fused sweep's triangles within
    `params.fused_reach_mm` x `scale` of the centre of the mask region of the (N, 3) mm `aligned`
    template: a sweep covers the sides of the head, which no single frame sees and the template does
    not reach, and registered on them too its face lands farther from the truth (`bench/RESULTS.md`
    section 19); any other scan whole, and a sweep whole where no triangle lies that near."""
    if not scan.fused_frames or params.fused_reach_mm is None:
        return scan
    part = mesh_scan_near(scan, aligned[mask_region(load_template())].mean(axis=0), params.fused_reach_mm * scale)
    return part if len(part.faces) else scan


@lru_cache(maxsize=1)
def template_basis(modes: int) -> ShapeBasis:
    """The template's ICT shape basis of `modes` identity modes (`morphable.ict_basis`), made once."""
    template = load_template()
    return ict_basis(template.vertices, template.faces, modes)


def registered(scan: Scan, alignment: Alignment, params: NonrigidParams = NonrigidParams(),
               quality: QualityParams = QualityParams()) -> tuple[Alignment, Registration, np.ndarray | None]:
    """Stage nonrigid: the alignment it kept, its registration, and, when detected landmarks are
    doubtful, the template registered from the face's shape alone ((n, 3) mm) for the quality gates
    to compare (else None). Detected landmarks are dropped for the landmark-free alignment, if that
    passes the face check, when they lie a median over `quality.detected_spread_refuse_mm` from their
    places on the registered face (a colour image not registered to its depth: the quality gates
    would refuse them), or when, doubtful, they place the mask region over
    `quality.shape_apart_drop_mm` from the shape's (`_cross_checked`)."""
    reg = register_template(scan, alignment, params)
    lm = alignment.landmarks
    if lm.path == "user" or not reg.landmark_spread_mm > quality.detected_spread_refuse_mm:
        return _cross_checked(scan, alignment, reg, params, quality)
    why = f"the landmarks found by {lm.path} lay a median {reg.landmark_spread_mm:.1f} mm from their places on the registered face"
    return *(_by_shape(scan, "; ".join(filter(None, (lm.rejected, why))), params) or (alignment, reg)), None


def placed_by_shape(scan: Scan, alignment: Alignment, reg: Registration, params: NonrigidParams = NonrigidParams(),
                    quality: QualityParams = QualityParams()) -> tuple[Alignment, Registration] | None:
    """The template aligned and registered from the face's shape alone, when detected landmarks lie a
    median over `quality.cross_check_spread_mm` (and at most `quality.detected_spread_refuse_mm`: else
    `registered` has tried it) from their places on the registered face, and the shape alone places
    it; else None."""
    doubt, stray = quality.cross_check_spread_mm, quality.detected_spread_refuse_mm
    if alignment.landmarks.path not in ("image", "render") or not doubt < reg.landmark_spread_mm <= stray:
        return None
    return _by_shape(scan, "", params)


def _cross_checked(scan: Scan, alignment: Alignment, reg: Registration, params: NonrigidParams,
                   quality: QualityParams) -> tuple[Alignment, Registration, np.ndarray | None]:
    """Doubtful detected landmarks checked against the face's shape alone (`placed_by_shape`). When
    the two place the mask region (both masks' seal bands) over `quality.shape_apart_drop_mm` apart
    (mean; fran, whose landmarks are right, reads up to 7.5), the landmarks have dragged the template
    off the face and are dropped for the shape's alignment and registration, with nothing left to compare."""
    shape = placed_by_shape(scan, alignment, reg, params, quality)
    if shape is None:
        return alignment, reg, None
    region = mask_region(load_template())
    apart = float(np.linalg.norm(reg.vertices[region] - shape[1].vertices[region], axis=1).mean())
    if apart <= quality.shape_apart_drop_mm:
        return alignment, reg, shape[1].vertices
    lm = alignment.landmarks
    why = f"the landmarks found by {lm.path} placed the mask region a mean {apart:.1f} mm from where the face's shape alone places it"
    return replace(shape[0], landmarks=replace(shape[0].landmarks, rejected="; ".join(filter(None, (lm.rejected, why))))), shape[1], None


def _by_shape(scan: Scan, rejected: str, params: NonrigidParams) -> tuple[Alignment, Registration] | None:
    """The landmark-free alignment (saying what was `rejected` for it) and its registration, or None
    if it fails the face check."""
    instead = landmark_free_alignment(scan.seen, load_template(), rejected)
    if instead is None:
        return None
    alignment = Alignment(*instead)
    return alignment, register_template(scan, alignment, params)


@dataclass(frozen=True)
class Design:
    """A custom cushion for a scan: every stage's result, the printable solid and its checks."""

    alignment: Alignment
    registration: Registration
    contact: Contact
    cushion: Cushion
    solid: object  # trimesh.Trimesh, checked
    checks: dict
    rim: RimGap  # the rim before its pressure-compensating pre-load, against the scan
    quality: Quality  # the scan's quality gates (none refuses: else no design)
    preload: Preload  # the rim set into the skin along the axis, along the seal curve
    mould_parts: dict  # {"mould_left" | "mould_right" | "mould_face" | "mould_core": trimesh.Trimesh}, checked as written (outputs.py)
    mould_draft: dict  # {part name: fabrication.draft.Draft}: its moulding surface along its pull direction
    fits: dict  # {"custom" | "stock": CushionFit}: the custom cushion at its recommended force, the best stock size at its own
    fit_params: FitParams
    states: tuple[StateFit, ...]  # both cushions in each sleep state (`sleep_states`), each at its awake force
    stock: StockComparison | None  # the stock cushion a clinic would fit on this face (None: not compared)
    frame: Frame  # the rigid frame the cushion fits into: connector, vents, valve, headgear anchors
    frame_checks: dict  # `check_closed` of the frame
    dead_space_ml: float  # the air between the face and the connector's bore
    stock_not_fitted: str = ""  # why no stock cushion is compared where one was asked for (no size seats on this face)

    def preload_at(self, points: np.ndarray) -> np.ndarray:
        """(K,) mm: the pre-load at the seal-curve point nearest each of (K, 3) `points`."""
        return self.preload.mm[cKDTree(self.contact.curve).query(points)[1]]


def _silent(stage: str) -> None:
    """The default stage callback: nothing."""


@dataclass(frozen=True)
class Placement:
    """The template placed on a scan, whatever the mask: the alignment kept, its registration, and
    the template registered from the face's shape alone ((n, 3) mm) where detected landmarks are
    doubtful (else None; `registered`)."""

    alignment: Alignment
    registration: Registration
    by_shape: np.ndarray | None


def place_template(scan: Scan, user_landmarks: Landmarks | None = None, on_stage: Callable[[str], None] = _silent,
                   params: NonrigidParams = NonrigidParams(), quality: QualityParams = QualityParams(),
                   landmark_noise: LandmarkNoise = LandmarkNoise()) -> Placement:
    """Stages landmarks, similarity and nonrigid: the template aligned and registered on a scan
    (`params`: the registration's; `quality`: the thresholds deciding which landmarks it keeps;
    `landmark_noise`: noise on the detected landmarks, for robustness studies)."""
    on_stage("landmarks and similarity")
    load_template()  # once, before the two threads ask for it
    with ThreadPoolExecutor(max_workers=1) as pool:  # made while the landmarks are found: the shape basis (0.5 s), the scan's rims (1.4 s at 1 M vertices)
        made = [pool.submit(template_basis, params.morphable.modes)] if params.morphable else []
        made.append(pool.submit(getattr, scan, "rims"))
        al = align(scan, user_landmarks, landmark_noise)
    for future in made:
        future.result()  # what failed raises here, not made again
    on_stage("non-rigid registration")
    return Placement(*registered(scan, al, params, quality))


def design(
    scan: Scan, mask: str, user_landmarks: Landmarks | None = None, params: CushionParams = CushionParams(),
    fit_params: FitParams = FitParams(), on_stage: Callable[[str], None] = _silent, submit=at_once,
    placement: Placement | None = None, stock: str | None = "best", quality: QualityParams = QualityParams(),
    registration: NonrigidParams = NonrigidParams(), landmark_noise: LandmarkNoise = LandmarkNoise(),
    solids_made: Callable[[trimesh.Trimesh, dict, trimesh.Trimesh], None] = lambda *solids: None,
) -> Design:
    """Scan to checked printable cushion and its evaluation: align, register, carry the seal over,
    design with a pressure-compensating pre-load, thicken, check, mould, then press the custom
    cushion onto the face awake and asleep, beside the stock cushion a clinic would fit
    (`fitting_stock` of `stock`: a size, "gauge" or "best"; None: no comparison). `on_stage(name)`
    is called as each stage starts; the stock sizes are made (while the template is placed) and
    seated by `submit` (`work.py`), alongside the design when that is a worker process's.
    `quality`: the gates' thresholds; `registration`: the nonrigid registration's parameters;
    `landmark_noise`: noise on the detected landmarks (none by default).
    `placement`: the template already placed on this scan (`place_template`, which is mask-free: one
    placement serves both masks), else placed here from `user_landmarks` or detection.
    `solids_made(solid, mould parts, frame mesh)` is called while the best stock size is pressed
    asleep (`StockFitting.comparison`'s `meanwhile`), for work on the custom solids that `submit`'s
    worker would otherwise wait through."""
    if stock:
        ahead(submit, stock_solids, mask, stock, params)
    placement = placement or place_template(scan, user_landmarks, on_stage, registration, quality, landmark_noise)
    require_dense(scan)
    al, reg = placement.alignment, placement.registration
    judged = assessed(scan, mask, placement, params, quality, on_stage)  # or refused: rescan
    face, contact = judged.face, judged.contact
    if stock and submit is at_once:
        on_stage("the stock sizes, each at its best seat")  # seated here and now: no worker seats them alongside
    fitting = fitting_stock(mask, face, stock, params, fit_params, submit) if stock else None
    on_stage("solid and checks")
    params = replace(params, frame_clearance_mm=ring_clearance(judged.neutral, face.registered))  # the dead space within its limit
    cushion, preload, solid, wall = compensated_cushion(contact, face, reg.vertices, params, fit_params)
    awake = fit_cushion(solid, face, params.flange_mm, None, fit_params)
    asleep = state_faces(face, sleep_states(mask))
    cushion, solid, membrane = enveloped_cushion(contact, face, reg.vertices, cushion, preload.mm, solid, fit_params, awake, asleep)
    solid = written_clean(solid)
    checks = _checked(cushion, solid, (wall, params.wall_mm), membrane, f"the {mask} cushion", al.landmarks.path)
    on_stage("pressure and leak, casting mould, frame")
    with ThreadPoolExecutor(max_workers=1) as pool:  # the mould and the frame (manifold3d's booleans) made while the cushion is pressed
        made = pool.submit(_mould_and_frame, cushion, solid)
        try:
            fits, states = pressed_asleep(face, {"custom": solid}, mask, params, fit_params, faces=asleep)
        finally:  # a mould or frame that fails its checks is the error reported
            moulded, frame, frame_checks = made.result()
    compared, unfitted = None, ""
    if fitting is not None:
        on_stage("the stock cushion a clinic would fit")
        try:
            compared = fitting.comparison(faces=asleep, meanwhile=lambda: solids_made(solid, moulded.parts, frame.mesh))
        except NoStockSeat as exc:  # the custom design stands, compared with none
            unfitted = str(exc)
        else:
            fits, states = fits | compared.fits, compared.beside(states)
    return Design(al, reg, contact, cushion, solid, checks, judged.rim, judged.quality, preload, moulded.parts, moulded.draft,
                  fits, fit_params, states, compared, frame, frame_checks, dead_space_ml(cushion, frame, face.registered), unfitted)


def _mould_and_frame(cushion: Cushion, solid: trimesh.Trimesh) -> tuple[Mould, Frame, dict]:
    """(the casting mould, the frame, the frame's `check_closed`) of a custom cushion and its solid."""
    moulded = mould(cushion, solid)
    frame = build_frame(cushion, solid)
    return moulded, frame, check_closed(frame.mesh, "the frame")


@dataclass(frozen=True)
class Assessed:
    """The seal carried onto a scan and the scan judged for it: the `face` cushions are pressed onto,
    the `contact`, the `neutral` cushion (before its pre-load), its `rim` against the scan, and the
    `quality` gates (none refuses)."""

    face: Face
    contact: Contact
    neutral: Cushion
    rim: RimGap
    quality: Quality


def assessed(scan: Scan, mask: str, placement: Placement, params: CushionParams = CushionParams(),
             quality: QualityParams = QualityParams(), on_stage: Callable[[str], None] = _silent) -> Assessed:
    """Stages contact and quality: the seal carried onto the placed template's scan, the cushion
    designed on it without pre-load, and the quality gates; raises QualityError where one refuses."""
    al, reg = placement.alignment, placement.registration
    on_stage("contact")
    face = face_for(scan, al, reg)  # its scan surface (and the surface's spatial indexes) serve every stage after
    contact = transfer_contact(load_template(), reg.vertices, face.scan, mask)
    on_stage("cushion")
    neutral = design_cushion(contact, face.axis, face.up, reg.vertices[NOSE_TIP], params)
    edge = neutral.grid(256, 2)[:, 0]
    rim = rim_gap(edge, contact.normals_at(edge), scan, face.scan)
    shape = proportions(load_template().vertices, al.similarity, reg)
    gates = require_quality(assess(scan, al.landmarks, reg, contact, rim, shape, placement.by_shape, quality))
    return Assessed(face, contact, neutral, rim, gates)


def _checked(cushion: Cushion, solid: trimesh.Trimesh, wall: tuple[float, float], membrane: tuple[float, float], name: str,
             landmarks_path: str) -> dict:
    """`check_solid` of a custom cushion (`wall`: thinnest measured and set thickness, mm; `membrane`:
    thinnest measured mm and least share of its set thickness). A cushion crossing itself is refused with its cause: its wall's surface crossing itself (a
    twisted seal curve, which a well-placed template does not carry: the refusal says what to do),
    its membrane's surface crossing itself, or, both clean, its solid folding where a surface bends
    tighter than it is thick."""
    try:
        return check_solid(solid, *wall, name, membrane)
    except SolidError as exc:
        crossings = exc.found.get("self_intersecting_edges", 0)
        if not crossings:
            raise
        if self_intersecting_edges(cushion_sheet(cushion)):
            cause = (f"the seal curve carried onto this scan is twisted, which a well-placed template does not give "
                     f"(landmarks by {landmarks_path}); give landmarks with --landmarks, or rescan facing the camera")
        elif cushion.membrane is not None and self_intersecting_edges(membrane_sheet(cushion)):
            cause = "its membrane's flaps run into each other where the seal bends tightly inwards, a shape of this face it cannot follow"
        else:
            cause = (f"its surface does not, but its {wall[1]:g} mm wall or {_thicknesses(cushion)} mm membrane folds where the "
                     "surface bends tighter than that, a shape of this face the cushion cannot follow")
        raise SolidError(f"{name} would cross itself ({crossings} self-intersecting edges): {cause}; nothing was written") from None


def _thicknesses(cushion: Cushion) -> str:
    """The membrane's set thickness (mm) as words: one figure, or its least and most."""
    t = cushion.membrane_thickness_at()
    return f"{t.min():.2g}-{t.max():.2g}" if np.ptp(t) > 0 else f"{t[0]:g}"


def face_for(scan: Scan, al: Alignment, reg: Registration, cushion: np.ndarray | None = None) -> Face:
    """The face cushions are pressed onto: the scan as it is seen (`Scan.seen`) within
    SURFACE_REACH_MM of the registered template's seal bands (both masks) or of a given `cushion`'s
    (V, 3) mm vertices, `thinned` to SEEN_CUBE_MM where still denser (a dense capture or fused
    sweep, a mesh dense only at the face), its registered template, the mask axis (the template's
    +z carried by the similarity) and the head's up direction (its +y). The seal curve is carried
    onto it and every cushion pressed on it, and the sleep states each move a copy of it with its
    own spatial indexes."""
    near = reg.vertices[mask_region(load_template())]
    surface = thinned(scan_surface(scan.seen, near if cushion is None else np.vstack([near, cushion]), SURFACE_REACH_MM), SEEN_CUBE_MM)
    return face_of(surface, reg.vertices, al.similarity.rotation[:, 2], al.similarity.rotation[:, 1])


def pressed_asleep(
    face: Face, cushions: dict[str, trimesh.Trimesh], mask: str, params: CushionParams = CushionParams(),
    fit_params: FitParams = FitParams(), force_n: float | None = None, faces: dict[FaceState, Face] | None = None,
) -> tuple[dict[str, CushionFit], tuple[StateFit, ...]]:
    """The `evaluated_cushions` pressed onto the face awake (`evaluate`) and in each sleep state of
    a `mask`, all at one headgear force: `force_n`, or the custom cushion's set for the states
    (`headgear_force`). `faces`: the face in each sleep state where already made (`state_faces`)."""
    fits = evaluate(face, cushions, params, fit_params, force_n)
    states = fit_states(cushions, face, sleep_states(mask), params.flange_mm, fits["custom"].force_n, fit_params, fits, faces=faces)
    force = fits["custom"].force_n if force_n is not None else headgear_force(fits["custom"], states, fit_params)
    if force == fits["custom"].force_n:
        return fits, states
    return ({name: at_force(fit, force, fit_params) for name, fit in fits.items()},
            tuple(replace(s, fits={name: at_force(fit, force, state_params(s.state, fit_params)) for name, fit in s.fits.items()})
                  for s in states))


def evaluated_cushions(
    al: Alignment, custom: trimesh.Trimesh, generic_mask: str | None, params: CushionParams = CushionParams(),
) -> dict[str, trimesh.Trimesh]:
    """The cushion meshes an evaluation presses onto the face: "custom", and for a `generic_mask`
    "generic" (the same design on the template, placed by the similarity)."""
    cushions = {"custom": custom}
    if generic_mask:
        cushions["generic"] = cushion_sheet(place(template_cushion(generic_mask, params), al.similarity))
    return cushions


def evaluate(
    face: Face, cushions: dict[str, trimesh.Trimesh], params: CushionParams = CushionParams(),
    fit_params: FitParams = FitParams(), force_n: float | None = None,
) -> dict[str, CushionFit]:
    """Stage evaluate: the `evaluated_cushions` pressed onto the face at one headgear force
    (`force_n`, or the one the custom cushion is designed for)."""
    fits = {"custom": fit_cushion(cushions["custom"], face, params.flange_mm, force_n, fit_params)}
    force = fits["custom"].force_n
    return fits | {name: fit_cushion(mesh, face, params.flange_mm, force, fit_params) for name, mesh in cushions.items() if name != "custom"}
