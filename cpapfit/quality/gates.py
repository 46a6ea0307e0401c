"""Quality gates: is the scan good enough for the mask designed on it?

Measured once the template is registered and the seal carried over (all mm):
- coverage: fraction of the mask's contact band (registered template vertices) with scan data
  within `near_mm`: a scan cropped, turned away, or with the nose's shadow over the seal;
- hole: the longest stretch of the seal curve with no scan data within `near_mm`, in mm along
  the seal: there the seal follows the template, not the patient;
- residual: median point-to-plane distance of the contact band's matched vertices to the scan:
  a noisy or moving scan, or a registration that did not reach the skin;
- landmarks: median distance from the landmarks to the scanned skin. Detected landmarks are
  lifted from the depth, so they lie on it; landmarks off it (another capture's coordinates, a
  wrong frame, a careless file) drag the registration, and the mask, along the skin where
  nothing in the geometry can pull it back. Landmark-free alignments (fallback) are not judged.
- landmark spread: the landmarks' median distance to their places on the face registered at the
  detected landmarks' weight (`Registration.landmark_spread_mm`). A user's: past the registration's
  trust they were not given the paper's weight, and the file deserves a look. Detected ones lie
  2-5 mm from their places (the detector's own error); far more, and the image has drifted from
  the geometry: a colour image not registered to its depth (a shift of 8 px, ~8 mm, gives 6-9 mm),
  or colours misplaced on a mesh. The registration holds such landmarks only partly, and the
  seal slides along the skin with them. Past the refusal threshold they are dropped before this
  (`pipeline.registered`) if the face's shape alone places the template;
- landmark-free: the template was placed by the face's shape alone (no face detected, or a
  detection rejected: its face failed the face check, or its landmarks lay far from the registered
  face). On synthetic subjects that is as good as landmarks; on the shared real face (fran) it put
  the seal curve 1.8-2.2 mm (at most 5.7 mm) from where the detected landmarks put it: always flagged;
- shape apart: detected landmarks that lie further from their places than the detector's usual
  error are doubtful; the template is then also placed by the face's shape alone and registered
  (`pipeline.placed_by_shape`), and the two seal bands compared. Neither can be told right from
  the geometry (a slide along the skin fits as well), so past the flag threshold the design is
  flagged; never refused (on fran the shape alone is the one that errs: 2.8-7.5 mm apart with its
  landmarks right). Past `shape_apart_drop_mm` the landmarks have dragged the template off the
  face (a bare mesh's shaded render: 12-23 mm) and are dropped for the shape
  (`pipeline.registered`), flagged landmark-free;
- face size and depth ratio (`proportions.py`): the registered face's size, and its depth for its
  breadth, against the template's (an adult's). A scale or units misstated makes the face, and the
  mask, that much too small or large; a focal length misstated by k makes it k times too deep for
  its breadth. Adult faces lie well inside the flag thresholds, so a face past them is more likely
  a misstated scan than a face, and it is said which setting to check;
- in front of the face (`in_front.py`): the area of scan surface over 5 mm out from the registered
  face over its middle (eyes, nose, mouth, chin): glasses, a hand, a tube or hair. Glasses rest their
  pads where the nasal seal goes: on synthetic subjects wearing a thin frame the seal lay up to
  0.8-2.9 mm off the skin, on the pads, mostly unflagged; clean faces read 0 mm²;
- lips apart (oronasal masks): how far apart the lips are (`landmarks/mouth.py`).
  The template's mouth is closed and does not follow a dropped jaw: on framed synthetic subjects
  whose lower lip moved 4 mm the oronasal seal region lands 0.9-2.7 mm off its place (closed:
  0.3-0.9), 8 mm 2.2-3.4 mm, with every other gate clean. Nasal masks are not affected.

Each gate flags "rescan advised" past its flag threshold and refuses the design past its refuse
threshold (`QualityParams`, calibrated on synthetic subjects: see bench/RESULTS.md).
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..align.nonrigid import Registration
from ..cushion.contact import Contact
from ..errors import QualityError
from ..evaluation.gap import SPACINGS, RimGap, data_reach, off_skin
from ..evaluation.rim import spacing
from .in_front import in_front_area_mm2
from ..landmarks.types import WITHOUT_COLOURS, Landmarks
from ..loops import longest_run
from .proportions import Proportions
from ..scan import Scan
from ..template import load_template
from ..thresholds import IN_FRONT_MM, QualityParams


@dataclass(frozen=True)
class Gate:
    """One measure and what it means: `flag` (rescan advised), `refuse` (no design), a one-line message."""

    code: str
    value: float
    flag: bool
    refuse: bool
    message: str


@dataclass(frozen=True)
class Quality:
    """Every gate's result for one design."""

    gates: tuple[Gate, ...]

    @property
    def flags(self) -> list[Gate]:
        return [g for g in self.gates if g.flag]

    @property
    def refused(self) -> list[Gate]:
        return [g for g in self.gates if g.refuse]

    def record(self) -> dict:
        """The fit.json keys: rescan_advised, warnings (code and message) and every measured value."""
        return {
            "rescan_advised": bool(self.flags),
            "warnings": [{"code": g.code, "message": g.message} for g in self.flags],
            "quality": {g.code: round(g.value, 4) for g in self.gates},
        }


def _gate(code: str, value: float, limits: tuple[float, float], what: str, advice: str, unit: str = " mm") -> Gate:
    """A gate on `value`, bad above its (flag, refuse) `limits`, or below them if flag > refuse;
    `what` says the value in words, `advice` what to do."""
    flag_at, refuse_at = limits
    low_is_bad = flag_at > refuse_at
    side = "below" if low_is_bad else "above"
    worse = (lambda a, b: a < b) if low_is_bad else (lambda a, b: a > b)
    scale = 100.0 if unit == " %" else 1.0
    refused = f"refused {side} {scale * refuse_at:g}{unit}" if np.isfinite(refuse_at) else "never refused"
    message = f"{what}; {advice} (rescan advised {side} {scale * flag_at:g}{unit}, {refused})"
    return Gate(code, float(value), worse(value, flag_at), worse(value, refuse_at), message)


def assess(scan: Scan, landmarks: Landmarks, registration: Registration, contact: Contact, rim: RimGap,
           shape: Proportions, by_shape: np.ndarray | None = None, params: QualityParams = QualityParams()) -> Quality:
    """The gates for the landmarks, the registration and the face's `shape` it gives, the seal it
    carried onto `scan` and the rim of the cushion designed on it; `by_shape`: the (n, 3) mm template
    registered from the face's shape alone, to compare (doubtful detected landmarks), or None."""
    p, mask = params, contact.mask
    tree = cKDTree(scan.vertices)
    band = load_template().regions[mask].band
    near = float(_has_data(scan, tree, registration.vertices[band], p.near_mm).mean())
    seal_gap = ~_has_data(scan, tree, contact.curve, p.near_mm)
    seal_mm = float(np.linalg.norm(contact.curve - np.roll(contact.curve, 1, axis=0), axis=1).sum())
    hole = longest_run(seal_gap, np.ones(len(seal_gap)))[0] * seal_mm / len(seal_gap)
    matched = registration.residual[band][registration.valid[band]]
    residual = float(np.median(matched)) if len(matched) else np.inf
    off_rim = rim.worst_stretch_mm()
    ahead = in_front_area_mm2(scan.vertices, tree, registration, load_template())
    gates = [
        _gate("coverage", near, (p.coverage_flag, p.coverage_refuse), f"the scan covers {100 * near:.0f} % of the {mask} mask's seal region",
              "rescan with the whole mask region (nose, cheeks, lips) in view, facing the camera", " %"),
        _gate("hole_mm", hole, (p.hole_flag_mm, p.hole_refuse_mm), f"{hole:.0f} mm of the {mask} seal lies over a hole in the scan",
              "the seal there is the template's guess: rescan to fill the hole"),
        _gate("residual_mm", residual, (p.residual_flag_mm, p.residual_refuse_mm),
              f"the registered face lies a median {residual:.2f} mm from the scan over the seal",
              "a noisy scan, or one that moved: rescan holding still"),
        _gate("in_front_mm2", ahead, (p.in_front_flag_mm2, p.in_front_refuse_mm2),
              f"{ahead:.0f} mm² of the scan stands over {IN_FRONT_MM:g} mm in front of the face around the eyes, nose and mouth",
              "glasses, a hand, a tube or hair between the camera and the skin? glasses rest on the nose where the seal goes: "
              "take them off, clear the face and rescan", " mm²"),
        _gate("rim_gap_mm", off_rim, (p.rim_gap_flag_mm, p.rim_gap_refuse_mm),
              f"the cushion's rim stands up to {off_rim:.1f} mm off the scanned skin over several mm of rim",
              "the template missed the face there: give landmarks with --landmarks, or rescan facing the camera"),
    ]
    if landmarks.path != "fallback":
        off = float(np.median(off_skin(scan, tree, landmarks.points, _reach(scan, tree, landmarks.points, p.near_mm))))
        gates.append(_gate("landmarks_mm", off, (p.landmarks_flag_mm, p.landmarks_refuse_mm),
                           f"the {landmarks.path} landmarks lie a median {off:.1f} mm off the scanned skin",
                           "they disagree with the geometry: check the landmarks file, or rescan"))
        if np.isfinite(registration.landmark_spread_mm):
            gates.append(_spread_gate(scan, landmarks, registration.landmark_spread_mm, p))
        if by_shape is not None:
            apart = float(np.linalg.norm(registration.vertices[band] - by_shape[band], axis=1).mean())
            gates.append(_gate("shape_apart_mm", apart, (p.shape_apart_flag_mm, p.shape_apart_refuse_mm),
                               f"the {mask} seal region the {landmarks.path} landmarks placed lies a mean {apart:.1f} mm from where "
                               "the face's shape alone places it, and the geometry cannot tell which is right",
                               f"check the landmarks picture ({_image_cause(scan, landmarks.note)}), or give landmarks with --landmarks"))
    else:
        why, cause = (landmarks.rejected, _image_cause(scan, landmarks.rejected)) if landmarks.rejected else ("no face was detected", _no_face_cause(scan))
        gates.append(Gate("landmark_free", 1.0, True, False, f"{why}, so the template was placed by the face's shape alone, which on a "
                          f"real face can put the seal a few mm from where landmarks put it; check the landmarks picture ({cause}), "
                          "or give landmarks with --landmarks"))
    return Quality(tuple(gates + _shape_gates(scan, shape, p) + _mouth_gates(mask, landmarks, p)))


def _reach(scan: Scan, tree: cKDTree, points: np.ndarray, least_mm: float) -> float | np.ndarray:
    """mm: how near a scan point must lie to each of (K, 3) points for the scan to have data there,
    at least `least_mm`. A depth image's points lie on its pixel grid: SPACINGS times its median
    spacing everywhere (at its holes' edges and in the islands between small holes the neighbours lie
    on one side, and a local spacing reads wide: 31 % of a seal region riddled with holes read 48 %).
    A mesh's or cloud's spacing varies (decimation): `data_reach`."""
    return max(least_mm, SPACINGS * spacing(tree)) if scan.is_capture else data_reach(tree, points, least_mm)


def _has_data(scan: Scan, tree: cKDTree, points: np.ndarray, least_mm: float) -> np.ndarray:
    """(K,) bool: a scan point lies within `_reach` of each of (K, 3) points."""
    return tree.query(points)[0] < _reach(scan, tree, points, least_mm)


def _mouth_gates(mask: str, landmarks: Landmarks, p: QualityParams) -> list[Gate]:
    """How far apart the lips are, for an oronasal mask whose landmarks say so (none otherwise)."""
    lips = landmarks.lips_apart_mm
    if mask != "oronasal" or not np.isfinite(lips):
        return []
    return [_gate("lips_apart_mm", lips, (p.lips_apart_flag_mm, p.lips_apart_refuse_mm),
                  f"the lips are {lips:.0f} mm apart: the mouth is open, and the template's closed mouth does not follow the "
                  "dropped jaw, so the seal's chin part lies off its place",
                  "rescan with the lips closed and the jaw relaxed (a nasal mask is not affected)")]


def _shape_gates(scan: Scan, shape: Proportions, p: QualityParams) -> list[Gate]:
    """The face's depth ratio and size against the template's, each judged on the side it lies
    (neither when under `proportions.MIN_MATCHED` template vertices met the scan: the coverage gate refuses
    that). The depth ratio comes first: off, it points to the focal length, which also shrinks or
    swells the size."""
    flat, small = shape.depth_ratio < 1.0, shape.size < 1.0
    focal = (f"check the capture's intrinsics (fx, fy): a focal length k times too {'short' if flat else 'long'} makes the face "
             f"k times too {'flat' if flat else 'deep'} and the mask k times too {'wide' if flat else 'narrow'}"
             if scan.is_capture else "check how the scan was made and exported: it looks stretched or squashed along one axis")
    scale = "the capture's depth scale and intrinsics (fx, fy)" if scan.is_capture else "the scan's units (state them with --units)"
    gates = [
        _gate("depth_ratio", shape.depth_ratio, (p.flat_face_flag, p.flat_face_refuse) if flat else (p.deep_face_flag, p.deep_face_refuse),
              f"the face is {100 * shape.depth_ratio:.0f} % as deep for its breadth as the template's (an adult man's)", focal, " %"),
        _gate("face_size", shape.size, (p.small_face_flag, p.small_face_refuse) if small else (p.large_face_flag, p.large_face_refuse),
              f"the face measures {100 * shape.size:.0f} % of the template's (an adult man's)",
              f"check {scale}: misstated, they make the mask as much too {'small' if small else 'large'}"
              + (" (or is this a child's face? the template and frame are an adult's)" if small else ""), " %"),
    ]
    return [g for g in gates if np.isfinite(g.value)]


def _image_cause(scan: Scan, found: str) -> str:
    """Why an image's face may disagree with a scan's geometry, in words; `found`: how that face was
    found (a `Landmarks` note, or what was rejected: a face found on renders drawn WITHOUT_COLOURS
    was not misled by them)."""
    if scan.is_capture:
        return "the colour image may not line up with the depth (register it to the depth image)"
    if (scan.colors is not None or scan.texture is not None) and WITHOUT_COLOURS not in found:
        return "the scan's colours may be misplaced on its surface, or the render may have misled the detector"
    return "the shaded render may have misled the detector"


def _no_face_cause(scan: Scan) -> str:
    """Why no face may have been detected on a scan, in words."""
    if scan.is_capture:
        return "the capture has no colour image: add color.png" if scan.image is None else "light the face evenly, facing the camera"
    return "the detector found no face on the scan's render"


def _spread_gate(scan: Scan, landmarks: Landmarks, spread: float, p: QualityParams) -> Gate:
    """The landmarks' median distance (mm) from their places on the face the geometry gives: a
    user's file against its trust, detected landmarks against the detector's own error."""
    path = landmarks.path
    if path == "user":
        limits, whose = (p.landmark_spread_flag_mm, p.landmark_spread_refuse_mm), "the landmarks file's points"
        advice = "they pulled only as hard as detected landmarks: check the file (indices, frame), or leave it out"
    else:
        limits, whose = (p.detected_spread_flag_mm, p.detected_spread_refuse_mm), f"the landmarks detected on the {path}"
        advice = f"{_image_cause(scan, landmarks.note)}: rescan, or give landmarks with --landmarks"
    return _gate("landmark_spread_mm", spread, limits,
                 f"{whose} lie a median {spread:.1f} mm from their places on the face the scan's geometry gives", advice)


def require_quality(quality: Quality) -> Quality:
    """The quality, or a QualityError naming the first gate that refuses."""
    if quality.refused:
        gate = quality.refused[0]
        raise QualityError(f"the scan is not good enough for a mask ({gate.code}): {gate.message}")
    return quality
