"""A cushion on a face under load: rim pressure, leak, the safety window, the force that seals;
and the pre-load that makes the custom cushion press evenly (pressure compensation)."""

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import trimesh
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from ..frozen import freeze_arrays
from ..normals import lean_mesh
from ..tangents import plane_across
from ..template import load_template
from .leak import leak_l_min
from .mechanics import COS_MIN, N_PER_KPA_MM2, Flaps, Pressed, cpap_load_n, least_force_n, press, pull_n
from .membrane import reach_mm, root_pull_kpa_mm
from .rim import RimContact, find_rim
from .tissue import Stiffness, TissueModel, stiffness

KPA_PER_CMH2O = 0.0980665
MAX_PRELOAD_MM = 5.0  # the most the rim is set into the skin anywhere
STEP_MM = 1.0  # a correction moves a seal point at most this far
NEAR_RAD = 0.05  # from the rim point in its direction about the axis: unit vectors across it this close (~3 degrees apart)
NEAR_MM = 3.0  # and no farther from the seal point than the flange's width and this
MMHG_PER_KPA = 7.50062


@dataclass(frozen=True)
class FitParams:
    """CPAP pressure (cmH2O); the safe window runs from the CPAP pressure plus `margin_kpa` up to
    the capillary closing pressure (`capillary_kpa`, 32 mmHg); `target_kpa`: the even rim pressure
    the compensated cushion is designed for; `max_force_n`: highest headgear force searched."""

    cpap_cmh2o: float = 10.0
    margin_kpa: float = 0.2
    capillary_kpa: float = 4.3
    target_kpa: float = 2.5
    max_force_n: float = 60.0
    tissue: TissueModel = field(default_factory=TissueModel)

    @property
    def cpap_kpa(self) -> float:
        return self.cpap_cmh2o * KPA_PER_CMH2O

    @property
    def window_kpa(self) -> tuple[float, float]:
        return self.cpap_kpa + self.margin_kpa, self.capillary_kpa

    def describe(self) -> dict:
        lo, hi = self.window_kpa
        return {"cpap_cmh2o": self.cpap_cmh2o, "cpap_kpa": round(self.cpap_kpa, 4), "window_kpa": [round(lo, 4), hi],
                "window_mmhg": [round(lo * MMHG_PER_KPA, 2), round(hi * MMHG_PER_KPA, 2)], "target_kpa": self.target_kpa}


CUSHIONS = ("custom", "stock", "stock_gauge", "generic")  # the cushions a fit record may hold, in the order they are shown


@dataclass(frozen=True)
class CushionFit:
    """One cushion pressed onto the face at `force_n` N of headgear.

    rim: the contact line (K points); stiffness: the tissue under it; pressure_kpa (K,) contact
    pressure, opening_mm (K,) seal opening the membrane (if any) leaves open, leak_l_min (K,) flow through it (NaN where the rim is
    not over scanned skin); pressed: the equilibrium over the covered points; seal_force_n: the
    least headgear force with no opening on the covered rim (None: not below max_force_n);
    contact_width_mm: the seal flange width (the contact band across the rim); window_kpa: the
    safe pressure window (low, high)."""

    rim: RimContact
    stiffness: Stiffness
    pressure_kpa: np.ndarray
    opening_mm: np.ndarray
    leak_l_min: np.ndarray
    pressed: Pressed
    force_n: float
    seal_force_n: float | None
    contact_width_mm: float
    window_kpa: tuple

    def __post_init__(self):
        freeze_arrays(self)

    @property
    def window_fraction(self) -> float:
        """The share (0 to 1) of the covered rim pressing within the safe window at this fit's force."""
        return _window_share(self.pressure_kpa[self.rim.covered], self.window_kpa)

    def summary(self) -> dict:
        """The numbers of fit.json for this cushion (over the covered rim)."""
        c = self.rim.covered
        p = self.pressure_kpa[c]
        top = int(np.argmax(p))
        gap = self.rim.clearance[c] - self.rim.clearance[c].min()
        return {
            "contact_fraction": float((p > 0).mean()),
            "pressure_mean_kpa": float(p.mean()),
            "pressure_cv": float(p.std() / p.mean()) if p.mean() > 0 else None,
            "pressure_max_kpa": float(p[top]),
            "pressure_max_mmhg": float(p[top] * MMHG_PER_KPA),
            "pressure_max_region": self.stiffness.region[np.flatnonzero(c)[top]],
            "window_fraction": self.window_fraction,
            "leak_l_min": float(self.leak_l_min[c].sum()),
            "seal_force_n": self.seal_force_n,
            "headgear_force_n": round(self.force_n, 3),
            "rim_covered_fraction": float(c.mean()),
            "gap_before_load_median_mm": float(np.median(gap)),
            "gap_before_load_max_mm": float(gap.max()),
            "shift_under_load_mm": self.pressed.shift_mm,
            "tilt_deg": np.degrees(np.arctan(self.pressed.tilt)).round(3).tolist(),
            "lifted_off": self.pressed.lifted,
            "membrane_sealed_fraction": float(((self.pressed.opening_mm > 0) & (self.opening_mm[c] == 0)).mean()),
            "membrane_width_mm": _least_median_most(self.rim.membrane_mm[c]),
            "membrane_thickness_mm": _least_median_most(self.rim.membrane_thickness_mm[c & (self.rim.membrane_mm > 0)]),
        }


def _least_median_most(values: np.ndarray) -> list[float]:
    """[least, median, most] of (N,) `values` mm, to the micrometre; zeros where N is 0."""
    return np.percentile(values, [0, 50, 100]).round(3).tolist() if len(values) else [0.0, 0.0, 0.0]


def _press_rim(rim: RimContact, k: np.ndarray, width_mm: float, force_n: float, cpap_kpa: float,
               flaps: Flaps | None = None, near: Pressed | None = None) -> Pressed:
    """`press` over the covered points of a rim with its membrane (`flaps`: `_flaps(rim, cpap_kpa)`,
    given or made), from `near` (its equilibrium at another force) where given."""
    c = rim.covered
    return press(rim.clearance[c], rim.cos[c], width_mm * rim.ds[c], k[c], rim.uv[c], rim.sealed_area_mm2, force_n, cpap_kpa,
                 _flaps(rim, cpap_kpa) if flaps is None else flaps, near)


def _pressing(rim: RimContact, k: np.ndarray, width_mm: float, cpap_kpa: float, flaps: Flaps) -> Callable[[float], Pressed]:
    """force N -> `_press_rim` of the rim at that force, each search started from the last one's
    equilibrium (the same within the search's tolerance)."""
    last = None

    def at(force: float) -> Pressed:
        nonlocal last
        last = _press_rim(rim, k, width_mm, force, cpap_kpa, flaps, last)
        return last

    return at


def _flaps(rim: RimContact, cpap_kpa: float) -> Flaps:
    """The membrane at the covered rim points: each flap's pull (`mechanics.pull_n`) and reach."""
    c = rim.covered
    width, thickness = rim.membrane_mm[c], rim.membrane_thickness_mm[c]
    return Flaps(pull_n(root_pull_kpa_mm(width, thickness, cpap_kpa), rim.ds[c], rim.cos[c]), reach_mm(width, thickness, cpap_kpa))


def _least_force(rim: RimContact, width_mm: float, cpap_kpa: float, flaps: Flaps) -> float:
    """N: the least headgear force that holds this rim on (`mechanics.least_force_n`), at least 0."""
    c = rim.covered
    return max(least_force_n(rim.cos[c], width_mm * rim.ds[c], rim.uv[c], rim.sealed_area_mm2, cpap_kpa, flaps.pull_n), 0.0)


def _left_open(pressed: Pressed, flaps: Flaps) -> np.ndarray:
    """(covered,) mm of each covered rim point's seal opening that its membrane (`flaps`) does not
    close (none does where the mask is lifted off the face)."""
    if pressed.lifted:
        return pressed.opening_mm
    return np.maximum(pressed.opening_mm - flaps.reach_mm, 0.0)


def seal_force(rim: RimContact, k: np.ndarray, width_mm: float, params: FitParams, tol_n: float = 0.01) -> float | None:
    """Least headgear force (N) at which no covered rim point is left open (bisection), or None."""

    flaps = _flaps(rim, params.cpap_kpa)
    pressed = _pressing(rim, k, width_mm, params.cpap_kpa, flaps)

    def opened(force: float) -> bool:
        return _left_open(pressed(force), flaps).max() > 0

    if opened(params.max_force_n):
        return None
    return _bisected(opened, _least_force(rim, width_mm, params.cpap_kpa, flaps), params.max_force_n, tol_n)[1]


def peak_force(rim: RimContact, k: np.ndarray, width_mm: float, params: FitParams, peak_kpa: float, tol_n: float = 0.01) -> float:
    """Most headgear force (N, up to `params.max_force_n`) at which no covered rim point presses
    harder than `peak_kpa` (bisection: the pressure grows with the force); the least force that
    holds the mask on where even the least contact presses harder."""
    flaps = _flaps(rim, params.cpap_kpa)
    pressed = _pressing(rim, k, width_mm, params.cpap_kpa, flaps)

    def over(force: float) -> bool:
        return pressed(force).pressure_kpa.max() > peak_kpa

    if not over(params.max_force_n):
        return params.max_force_n
    return _bisected(lambda force: not over(force), _least_force(rim, width_mm, params.cpap_kpa, flaps), params.max_force_n, tol_n)[0]


def window_force(rim: RimContact, k: np.ndarray, width_mm: float, params: FitParams, lo_n: float, hi_n: float, steps: int = 16) -> float:
    """N: the least headgear force from `lo_n` to `hi_n` (`steps` + 1 even steps) at which the most
    covered rim points press within the safe window; `lo_n` where `hi_n` is no more."""
    if hi_n <= lo_n:
        return lo_n
    pressed = _pressing(rim, k, width_mm, params.cpap_kpa, _flaps(rim, params.cpap_kpa))
    forces = np.linspace(lo_n, hi_n, steps + 1)
    shares = [_window_share(pressed(f).pressure_kpa, params.window_kpa) for f in forces]
    return float(forces[np.argmax(shares)])


def _window_share(pressure_kpa: np.ndarray, window_kpa: tuple) -> float:
    """The share of (K,) rim pressures (kPa) within the safe window (low, high) kPa."""
    low, high = window_kpa
    return float(((pressure_kpa >= low) & (pressure_kpa <= high)).mean())


def _bisected(below: Callable[[float], bool], lo: float, hi: float, tol_n: float) -> tuple[float, float]:
    """(lo, hi) N within `tol_n` of where `below(force)`, true up to a force and false past it, turns false."""
    while hi - lo > tol_n:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if below(mid) else (lo, mid)
    return lo, hi


def recommended_force(rim: RimContact, k: np.ndarray, width_mm: float, params: FitParams) -> float:
    """Headgear force (N) that holds the target pressure over the whole covered rim and balances the
    CPAP load: what a cushion compensated for this face needs."""
    c = rim.covered
    cos = np.maximum(rim.cos[c], COS_MIN)
    contact = params.target_kpa * width_mm * rim.ds[c] @ cos
    return float(contact * N_PER_KPA_MM2 + cpap_load_n(params.cpap_kpa, rim.sealed_area_mm2))


@dataclass(frozen=True)
class Face:
    """What a cushion is pressed onto (mm, scan frame): the scan's surface (or point cloud), the
    registered template (finds the rim, tells the tissue), the unit mask axis (out of the face)
    and the head's up direction."""

    scan: trimesh.Trimesh | trimesh.PointCloud
    registered: trimesh.Trimesh
    axis: np.ndarray
    up: np.ndarray

    def __post_init__(self):
        freeze_arrays(self)

    def __reduce__(self):
        """Pickled (for a worker process) as its meshes' arrays, never their caches: a process pool
        pickles in a thread of its own, while this process may be adding to those caches (a first
        query builds an index), and a dict that grows while it is pickled stops the run."""
        return _face, (*_arrays(self.scan), *_arrays(self.registered), self.axis, self.up)


def _arrays(mesh: trimesh.Trimesh | trimesh.PointCloud) -> tuple[np.ndarray, np.ndarray | None]:
    """(vertices, triangles or None for a point cloud) of a mesh, as plain arrays."""
    return np.asarray(mesh.vertices), np.asarray(mesh.faces) if isinstance(mesh, trimesh.Trimesh) else None


def _mesh(vertices: np.ndarray, faces: np.ndarray | None) -> trimesh.Trimesh | trimesh.PointCloud:
    """The mesh of `_arrays`' (vertices, triangles or None), its normals set (`normals.lean_mesh`)."""
    return trimesh.PointCloud(vertices) if faces is None else lean_mesh(vertices, faces)


def _face(scan_vertices, scan_faces, vertices, faces, axis, up) -> Face:
    """The `Face` of `Face.__reduce__`'s arrays."""
    return Face(_mesh(scan_vertices, scan_faces), _mesh(vertices, faces), axis, up)


def face_of(surface: trimesh.Trimesh | trimesh.PointCloud, warped: np.ndarray, axis: np.ndarray, up: np.ndarray) -> Face:
    """The `Face` of a scan's surface (`scan_surface`) and its registered template vertices `warped` (N, 3) mm."""
    return Face(surface, trimesh.Trimesh(warped, load_template().faces, process=False), axis, up)


def fit_cushion(cushion: trimesh.Trimesh, face: Face, width_mm: float, force_n: float | None, params: FitParams = FitParams()) -> CushionFit:
    """A cushion mesh (mm, scan frame) pressed onto a face along its mask axis at `force_n` N
    (None: the recommended force for this rim); `width_mm` the seal flange width."""
    return fit_rim(find_rim(cushion, face.scan, face.registered, face.axis, face.up), face, width_mm, force_n, params)


def fit_rim(rim: RimContact, face: Face, width_mm: float, force_n: float | None, params: FitParams = FitParams()) -> CushionFit:
    """`fit_cushion` of a cushion whose contact line on this face is `rim` (the same cushion at
    another force: `at_force`)."""
    k = stiffness(face.registered.kdtree.query(rim.points)[1], params.tissue)
    force = recommended_force(rim, k.effective, width_mm, params) if force_n is None else force_n
    return _fitted(rim, k, width_mm, force, seal_force(rim, k.effective, width_mm, params), params)


def at_force(fit: CushionFit, force_n: float, params: FitParams = FitParams()) -> CushionFit:
    """`fit`'s cushion on the same face at another headgear force `force_n` N (its contact line,
    springs and seal force are the same; `params` those it was fitted with)."""
    return _fitted(fit.rim, fit.stiffness, fit.contact_width_mm, force_n, fit.seal_force_n, params)


def _fitted(rim: RimContact, k: Stiffness, width_mm: float, force_n: float, sealing: float | None, params: FitParams) -> CushionFit:
    """The `CushionFit` of a rim on springs `k` pressed at `force_n` N, its seal force `sealing`."""
    flaps = _flaps(rim, params.cpap_kpa)
    pressed = _press_rim(rim, k.effective, width_mm, force_n, params.cpap_kpa, flaps)
    c = rim.covered
    opening = _left_open(pressed, flaps)
    leak = leak_l_min(opening, rim.ds[c], width_mm, params.cpap_kpa)
    full = [_spread(c, a) for a in (pressed.pressure_kpa, opening, leak)]
    return CushionFit(rim, k, *full, pressed, force_n, sealing, width_mm, params.window_kpa)


def _spread(covered: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(K,) values on the covered points, NaN elsewhere."""
    out = np.full(len(covered), np.nan)
    out[covered] = values
    return out


def compensating_preload(
    curve: np.ndarray, normals: np.ndarray, axis: np.ndarray, warped: np.ndarray, smoothing: float, params: FitParams = FitParams(),
) -> np.ndarray:
    """(K,) mm to set each seal point (K, 3) into the skin along the axis so that, pushed home,
    every point presses with the target pressure: soft tissue gets more pre-load, the stiff
    nasal bridge none; smoothed along the curve (Gaussian, `smoothing` samples) so the rim does
    not bend tighter than its wall. `normals` (K, 3) skin normals; `warped` the registered template."""
    k = stiffness(cKDTree(warped).query(curve)[1], params.tissue).effective
    need = params.target_kpa / (k * np.maximum(np.abs(normals @ axis), COS_MIN))  # axial indentation, mm
    return _bounded(gaussian_filter1d(np.minimum(need, need.min() + MAX_PRELOAD_MM), smoothing, mode="wrap"))


def refined_preload(preload: np.ndarray, curve: np.ndarray, fit: CushionFit, smoothing: float, params: FitParams = FitParams()) -> np.ndarray:
    """The pre-load (K,) mm along `curve` (K, 3) corrected by what pressing the cushion built with
    it gave (`fit`): each point goes deeper by (target - pressure) / axial stiffness at the covered
    rim point in its direction about the axis (within NEAR_RAD), wherever across the flange that
    lies (within its width and NEAR_MM of the point); none where there is no such rim point."""
    c = fit.rim.covered
    centre = fit.rim.points.mean(axis=0)
    turn, near = cKDTree(_around(fit.rim.points[c], centre, fit.rim.axis)).query(_around(curve, centre, fit.rim.axis))
    apart = np.linalg.norm(fit.rim.points[c][near] - curve, axis=1)
    axial = fit.stiffness.effective[c][near] * np.maximum(fit.rim.cos[c][near], COS_MIN)
    on = (turn <= NEAR_RAD) & (apart <= fit.contact_width_mm + NEAR_MM)
    correction = np.where(on, (params.target_kpa - fit.pressure_kpa[c][near]) / axial, 0.0)
    return _bounded(preload + gaussian_filter1d(np.clip(correction, -STEP_MM, STEP_MM), smoothing, mode="wrap"))


def _around(points: np.ndarray, centre: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(K, 2): where (K, 3) mm points lie around the unit `axis` through `centre`, as unit vectors across it."""
    return trimesh.util.unitize((points - centre) @ plane_across(axis).T)


def _bounded(preload: np.ndarray) -> np.ndarray:
    """Pre-loads shifted so that the least is zero (the rest of the shift is the mask's travel) and
    capped at MAX_PRELOAD_MM: where more would be needed (skin nearly parallel to the axis, where
    pushing along the axis hardly presses), the geometry cannot compensate and the evaluation says so."""
    return np.minimum(preload - preload.min(), MAX_PRELOAD_MM)
