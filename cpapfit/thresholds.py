"""Every threshold that accepts, flags, drops or refuses something, in one place (mm unless named).

Each module that applies one imports it from here; the quality gates' thresholds are `QualityParams`
(the defaults below, a caller may pass others through `cpapfit.Params.quality`). How each was set
is said beside it and measured in bench/RESULTS.md.
"""

from dataclasses import dataclass

import numpy as np

# --- Scan input (`cpapfit/io/`) ---
MAX_VERTICES = 2_000_000  # a larger mesh or cloud is refused before it is read
MAX_TRIANGLES = 4_000_000
MIN_VERTICES = 100  # fewer: no scan of a face
MIN_VALID_PIXELS = 500  # a depth image with fewer valid pixels is refused
DEPTH_RANGE_MM = (100.0, 2000.0)  # depth outside this range is treated as invalid
HEAD_MM = 600.0  # the largest robust extent (mm) of a scan of a face, or of the whole head: more is a bust or a scene
FACE_EXTENT_MM = (70.0, HEAD_MM)  # largest robust extent of a scan of a face (and at most the head)
# ... of a scan with more than the face in it (head, shoulders, chest): taken when stated, and by
# auto in mm, m or um, where it cannot be mistaken for a face in another unit.
BUST_EXTENT_MM = (HEAD_MM, 2000.0)
MIN_SHARED_EDGES = 0.5  # a mesh is a surface when this fraction of its edges join exactly two triangles,
MAX_NONMANIFOLD_EDGES = 0.05  # at most this fraction join three or more,
MAX_DEGENERATE = 0.5  # and at most this fraction of its triangles has no area
DEGENERATE_AREA = 1e-12  # a triangle's area below this x the scan's extent squared is none
MIN_USER_LANDMARKS = 4  # a landmarks file with fewer is refused
CUSHION_SIZE_MM = (20.0, 250.0)  # a cushion to evaluate: its largest extent, nasal to full-face

# --- A sweep of depth frames (`fusion.py`, `FusionParams`) ---
SWEEP_MIN_DEPTH_FRACTION = 0.3  # a frame with fewer valid pixels than this share of the sweep's median has no depth: dropped
SWEEP_MIN_OVERLAP = 0.6  # a frame whose points the model pairs fewer of (ICP fitness, finest radius) is not tracked: dropped
SWEEP_MAX_RMS_MM = 1.5  # ... or whose pairs lie further apart (RMS)
SWEEP_MIN_FRAMES = 3  # fewer tracked frames: the sweep is refused

# --- Landmark detection (`cpapfit/landmarks/`) ---
MIN_DETECTION_CONFIDENCE = 0.5  # MediaPipe's face detection
MIN_LANDMARKS = 30  # fewer lifted landmarks than this is no detection
MIN_INLIERS = 60  # a detection must have this many landmarks agreeing with the similarity
TWO_FACES_MM = 120.0  # two detections placing the face this far apart (mm) are two heads (a head is ~150 mm wide)
BLUE_SKIN_TINT = -0.05  # a detected face whose median (R - B) / (R + G + B) is below this is blue: channels swapped
LIFT_MIN_VALID_FRACTION = 0.4  # a landmark is lifted to 3-D from a depth window with at least this share valid
LIFT_MAX_SPREAD_MM = 6.0  # a window straddling a depth edge (spread of valid depths) is not trusted

# --- The face check (`align/check.py`): a placed template passes all of them ---
MIN_COVERAGE = 0.5
MAX_MEDIAN_GAP_MM = 3.5
MIN_RIDGE_MM = 6.0
MIN_BELOW_MM = 8.0
LOW_NOSE_MM = 2.5  # a nose this high above its sides and below, short of the two above, passes with a second look's agreement
SCALE_RANGE = (0.7, 1.4)
MAX_TURNED_DEG = 90.0
SPARSE_DEPTH = 0.6  # a capture with depth at less of its face's points' pixels is said to be riddled with holes (gates nothing; 30 % of pixels dropped at random: 0.62, designed; 50 %: 0.44, refused; the TrueDepth frame 0.87)

# --- Alignment (`align/initial.py`) ---
# A face found on renders framed by the landmark-free alignment's pose is the face that alignment
# found: its size within this factor of it (48 synthetic meshes and clouds: 0.91-1.10; fran as a
# bare STL, whose shape alone overstates its size: 0.86; a bare mesh's shaded render once gave a
# "face" at 0.75 that passed the face check, 15 mm off).
FRONT_SIZE = 1.25
# A detection failing the face check and the shape's own placement this far apart (mean, mm, over both
# masks' contact bands): one of them is on the wrong part of the face, and the design is refused.
DISAGREE_MM = 10.0
# A user's landmarks keep the paper's weight in the registration only within this median distance
# (mm) of their places on the face registered at low weight (`align/nonrigid.py`).
USER_TRUST_MM = 2.2

# --- Quality gates (`cpapfit/quality/`) ---
IN_FRONT_MM = 5.0  # scan this far out from the registered face is not skin (the in-front gate's measure)
MIN_MATCHED = 200  # fewer template vertices on the scan: no proportions measured (the coverage gate refuses)


@dataclass(frozen=True)
class QualityParams:
    """Thresholds of the gates. Past *_flag: "rescan advised" (fit.json, report); past *_refuse: no design.

    near_mm: scan data this close (mm) counts as present (coverage, hole; landmarks on the skin); for
        a coarse scan 1.5 times its point spacing if that is more (a point between vertices is that
        far from one): a depth image's pixel pitch, a mesh's or cloud's spacing there, at most 10 mm
        (`_reach`).
    coverage_*: fraction of the seal band with scan data (bad below).
    hole_*_mm: longest stretch of the seal over a hole, mm along the seal (bad above).
    residual_*_mm: median registration residual over the seal band, mm (bad above).
    landmarks_*_mm: median distance of the landmarks from the scanned skin, mm (bad above).
    landmark_spread_*_mm: a user's landmarks' median distance along the face from their places on
        it, mm (bad above); flagged where the registration stops trusting them.
    detected_spread_*_mm: the same for detected landmarks, mm (bad above).
    cross_check_spread_mm: detected landmarks with a spread above this (mm) are cross-checked against
        the face's shape alone: the detector's own error gives 2-5 mm on captures (one synthetic
        subject of 50 at 5.08), fran 4.4-4.8, bare meshes 3.4-6.3.
    shape_apart_*_mm: mean distance (mm) between the seal bands the landmarks and the shape alone
        place (bad above; never refused: the shape alone ends ~1 mm from the truth, so 1.5 mm apart may
        be 2 mm off); past shape_apart_drop_mm the landmarks are dropped.
    rim_gap_*_mm: the cushion rim's largest gap to the scanned skin over ~9 mm of rim (running
        median, `RimGap.worst_stretch_mm`), mm (bad above): where the scan has data the rim sits on
        it by construction (<= 0.6 mm), unless the template missed the face there.
    small_face_* / large_face_*: the face's size against the template's (`Proportions.size`, bad
        below / above).
    flat_face_* / deep_face_*: its depth for its breadth against the template's
        (`Proportions.depth_ratio`, bad below / above).
    in_front_*_mm2: area of scan over 5 mm in front of the middle of the registered face, mm² (bad
        above): 0 on synthetic subjects and the shared real scans, 198-349 with a thin glasses frame.
    lips_apart_*_mm: how far apart the lips are (`landmarks/mouth.py`), mm (bad above; oronasal
        masks only): closed mouths read 0-0.8 mm on synthetic captures, 0-5.3 mm on the same as
        meshes (holes along the lips' crease; 6.5 on a partial view pitched 23°), 0 on the shared
        real scans.
    Calibrated on synthetic subjects (bench/RESULTS.md): clean subjects are never refused; the
    flags mark the scans with much of the seal unseen, noisy depth, or landmarks off the skin. The
    face's proportions, over 959 synthetic designs with nothing misstated: size 0.83-1.16, depth
    ratio 0.86-1.12; the shared real scans 0.96-0.98 and 0.97-0.99. Real faces differ more in depth:
    1 000 ICT Face Model subjects read size 0.82-1.16 and depth ratio 0.65-1.29 over a capture's view
    (`bench/ict_proportions.py`), which the depth ratio's refusal bounds lie outside.
    """

    near_mm: float = 2.0
    coverage_flag: float = 0.75
    coverage_refuse: float = 0.4
    hole_flag_mm: float = 30.0
    hole_refuse_mm: float = 100.0
    residual_flag_mm: float = 0.5
    residual_refuse_mm: float = 1.5
    landmarks_flag_mm: float = 1.0
    landmarks_refuse_mm: float = 5.0
    landmark_spread_flag_mm: float = USER_TRUST_MM
    landmark_spread_refuse_mm: float = 10.0
    detected_spread_flag_mm: float = 7.0
    detected_spread_refuse_mm: float = 10.0
    cross_check_spread_mm: float = 5.0
    shape_apart_flag_mm: float = 1.5
    shape_apart_refuse_mm: float = np.inf
    shape_apart_drop_mm: float = 10.0
    rim_gap_flag_mm: float = 1.0
    rim_gap_refuse_mm: float = 3.0
    small_face_flag: float = 0.8
    small_face_refuse: float = 0.7
    large_face_flag: float = 1.25
    large_face_refuse: float = 1.5
    flat_face_flag: float = 0.75
    flat_face_refuse: float = 0.62
    deep_face_flag: float = 1.18
    deep_face_refuse: float = 1.35
    in_front_flag_mm2: float = 30.0
    in_front_refuse_mm2: float = 150.0
    lips_apart_flag_mm: float = 7.0
    lips_apart_refuse_mm: float = 11.0


# --- The mask's frame (`fabrication/dead_space.py`) ---
DEAD_SPACE_LIMIT_ML = {"nasal": 120.0, "oronasal": 300.0}  # the most air between the face and the connector, ml

# --- Printability (`fabrication/files.py`, `fabrication/draft.py`) ---
WALL_TOLERANCE = 0.95  # the thinnest wall may fall this far short of the set thickness
ZERO_AREA_MM2 = 1e-10  # a triangle of a written file with less area is degenerate: float32 corners ~100 mm out resolve ~1e-5 mm
MIN_DRAFT_DEG = 1.0  # a mould part's face with less draft than this is flagged
UNDERCUT_DEG = -0.1  # below this a face locks against the pull (a small tolerance for flat walls' rounding)
MAX_UNDERCUT, MAX_BELOW_MIN = 0.05, 0.05  # the mould's target: fractions of a part's moulding area undercut, under MIN_DRAFT_DEG

# --- Evaluation (`cpapfit/evaluation/`) ---
MIN_COVERED = 0.1  # less of the rim over scanned skin: nothing to evaluate

# --- The report's advice (`report/advice.py`) ---
LOW_CONFIDENCE = 0.5  # a landmark below this weight disagrees with the others
LOW_CONFIDENCE_SHARE = 0.2  # warn when more than this share of the landmarks is low
HOLE_MM = 8.0  # warn when the scan has no data under a longer stretch of the seal
SEAL_ON_SCAN = 0.9  # warn when less of the seal curve lies on scan data
