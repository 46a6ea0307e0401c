"""Design for the sleeping face: the membrane sized so that the cushion seals in every predicted state.

The wall, with its pressure-compensating pre-load, is pressed onto each state of `sleep_states`
predicted from the patient's registered template (the jaw dropped, the mask pushed and rolled by a
pillow, the CPAP range) at the awake headgear force. At each rim point the widest seal opening over
the states it stays on in (a state that lifts the mask off the face is a matter of headgear force,
not of the seal) that are pressed at one CPAP pressure (the awake face and the states without a
pressure of their own at the awake one, the range's ends at theirs), over the WINDOW sectors beside
it, grown by MARGIN_MM and MARGIN_SHARE for the prediction's doubt, is the reach its membrane needs
at that pressure, at most WIDEST_MM; and at least MARGIN_MM at the lowest pressure everywhere (the
prediction's margin, and no more: flaps that reach 2 mm there everywhere, as a stock cushion's,
seal some cushions set 10 mm off their place). The membrane's width is the narrowest flap of the
cushion's membrane thickness that reaches each of those at its pressure
(`evaluation.membrane.width_for`), and at most INWARD_SHARE of the width at which it and its
neighbours would meet (where the seal curve bends tightly inwards, beside a nostril, the flaps fan
out across the bend, `flap_directions`, but still run together). Wherever the membrane's sheet
still turns back on itself or closes up across the seal (`twisted_columns`), those columns narrow
by SHRINK, and the whole membrane while its solid would cross itself; beside a stretch of a face's
own flaps (not the stock family's) so narrowed, its neighbours step down to it by at most TAPER_MM
a column (`tapered`: a sudden step in width folds the sheet beside it, which would narrow it
further there). Where a flap falls short of its need, its sheet is thinner, down to THINNEST_MM
(`flap_thickness`): the reach grows as the cube of the thickness falls, so a flap that cannot
widen still closes the opening. A flap falls short where it was narrowed, and where it is laid
along skin that curves under it: it then runs from the seal curve to its free edge in a straight
line (`built_widths`, as the evaluation reads a flap across its section) shorter than asked.
"""

from dataclasses import replace

import numpy as np
import trimesh
from scipy.ndimage import maximum_filter1d
from scipy.spatial import cKDTree

from .contact import Contact, closed_resample
from .generic import NOSE_TIP
from .nurbs import AROUND, Cushion, CushionParams, design_cushion, flap_directions
from .solid import with_membrane
from ..evaluation.fit import KPA_PER_CMH2O, CushionFit, Face, FitParams, peak_force, window_force
from ..evaluation.membrane import reach_mm, width_for
from ..evaluation.rim import SECTORS
from ..evaluation.states import CPAP_RANGE_CMH2O, FaceState, StateFit, fit_states, sleep_states

MARGIN_MM, MARGIN_SHARE = 0.75, 0.25
WIDEST_MM = 8.0  # the most any rim point's membrane need reach: a stock full-face flap's
WINDOW = SECTORS // AROUND  # sectors each side: a control column's share of the rim
INWARD_SHARE = 0.7  # of the width at which neighbouring flaps meet: the free edge then runs 0.3 times the length of its root
SHRINK, SHRINKS = 0.75, 6
TAPER_MM = 1.0  # mm per control column (about 6 mm of seal): a flap narrowed where its sheet twists steps down over its neighbours
THINNEST_MM = 0.3  # the thinnest membrane: the reach law holds to the finite elements within 0.15 mm down to it (section 15)
THICKNESS_STEPS = 10  # bisection steps for a flap's thickness: to 0.2 um
PEAK_MARGIN_KPA = 0.4  # the headgear force stops where the awake peak comes this far under capillary closing (the prediction's doubt)
CLOSING = 1.0 - INWARD_SHARE  # a sheet row closes up where its step around is under this share of its root's
LOWEST_CPAP_KPA = CPAP_RANGE_CMH2O[0] * KPA_PER_CMH2O


def needed_reach(states: tuple[StateFit, ...], awake: CushionFit, awake_kpa: float) -> dict[float, np.ndarray]:
    """{CPAP kPa: (SECTORS,) mm}: the reach the membrane needs at each rim sector at each pressure
    the face is pressed at (`awake` and the states without a CPAP pressure of their own at
    `awake_kpa`), and at least MARGIN_MM at the lowest (module docstring)."""
    widest = {awake_kpa: np.nan_to_num(awake.opening_mm)}
    for fits in states:
        fit = fits.fits.get("custom")
        if fit is not None and not fit.pressed.lifted:
            kpa = awake_kpa if fits.state.cpap_cmh2o is None else fits.state.cpap_cmh2o * KPA_PER_CMH2O
            widest[kpa] = np.maximum(widest.get(kpa, 0.0), np.nan_to_num(fit.opening_mm))
    need = {kpa: np.minimum(maximum_filter1d(w, size=2 * WINDOW + 1, mode="wrap") * (1.0 + MARGIN_SHARE) + MARGIN_MM, WIDEST_MM)
            for kpa, w in widest.items()}
    need[LOWEST_CPAP_KPA] = np.maximum(need.get(LOWEST_CPAP_KPA, 0.0), MARGIN_MM)
    return need


def headgear_force(awake: CushionFit, states: tuple[StateFit, ...], params: FitParams) -> float:
    """N: the headgear force the custom cushion is set to: the larger of the recommended force
    (`awake.force_n`, the even target pressure's) and the least that seals the awake face and each
    state at the awake CPAP pressure (their seal forces; one that no force up to the limit seals
    asks for the most allowed), held to the force at which the awake peak comes PEAK_MARGIN_KPA
    under the capillary closing pressure but never below the awake seal force; then raised within
    that limit to the least force that keeps the most of the awake rim in the safe window."""
    most = peak_force(awake.rim, awake.stiffness.effective, awake.contact_width_mm, params, params.capillary_kpa - PEAK_MARGIN_KPA)
    seals = [awake.seal_force_n] + [s.fits["custom"].seal_force_n for s in states if s.state.cpap_cmh2o is None and "custom" in s.fits]
    need = [most if f is None else f for f in seals]
    force = max(min(max([awake.force_n, *need]), most), need[0])
    return window_force(awake.rim, awake.stiffness.effective, awake.contact_width_mm, params, force, most)


def column_need(need: dict[float, np.ndarray], rim: np.ndarray, contact: Contact) -> dict[float, np.ndarray]:
    """{CPAP kPa: (AROUND,) mm}: the `need` {CPAP kPa: (SECTORS,) mm} at the awake `rim` points
    (SECTORS, 3) nearest each control column of the seal curve."""
    nearest = cKDTree(rim).query(closed_resample(contact.curve, AROUND))[1]
    return {kpa: reach[nearest] for kpa, reach in need.items()}


def flap_widths(need: dict[float, np.ndarray], contact: Contact, thickness_mm: float) -> np.ndarray:
    """(AROUND,) mm: at each control column of the seal curve the narrowest flap `thickness_mm`
    thick that reaches `need` {CPAP kPa: (AROUND,) mm} at each of those pressures, at most
    INWARD_SHARE of the width at which the column's flap meets either neighbour (`converging`)."""
    seal = closed_resample(contact.curve, AROUND)
    normals = trimesh.util.unitize(closed_resample(contact.curve, AROUND, contact.normals))
    width = np.max([width_for(reach, thickness_mm, kpa) for kpa, reach in need.items()], axis=0)
    closing = converging(seal, flap_directions(seal, normals))
    return np.minimum(width, INWARD_SHARE / np.maximum(np.maximum(closing, np.roll(closing, 1)), 1e-9))


def flap_thickness(need: dict[float, np.ndarray], widths: np.ndarray, thickness_mm: float) -> np.ndarray:
    """(AROUND,) mm: at each control column the thickest membrane, from THINNEST_MM to
    `thickness_mm`, whose flap `widths` (AROUND,) mm wide reaches `need` {CPAP kPa: (AROUND,) mm}
    at each of those pressures (bisection: the reach falls as the sheet thickens); THINNEST_MM
    where none does (`thickness_mm` where that is thinner still)."""
    def reaches(thickness: np.ndarray) -> np.ndarray:
        return np.all([reach_mm(widths, thickness, kpa) >= reach for kpa, reach in need.items()], axis=0)

    lo, hi = np.full(len(widths), min(THINNEST_MM, thickness_mm)), np.full(len(widths), float(thickness_mm))
    for _ in range(THICKNESS_STEPS):
        mid = 0.5 * (lo + hi)
        ok = reaches(mid)
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return np.where(reaches(np.full(len(widths), float(thickness_mm))), thickness_mm, lo)


def converging(roots: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(K,) 1/mm: how fast each flap and the next close on each other per mm they run, from roots
    (K, 3) around a closed curve along unit `directions` (K, 3): the shortening of the gap between
    their free edges per mm of width over the gap between their roots (1/R for flaps pointing at
    the centre of a circle of radius R; negative where they spread)."""
    gap = np.roll(roots, -1, axis=0) - roots
    along = trimesh.util.unitize(gap)
    return -np.einsum("ij,ij->i", np.roll(directions, -1, axis=0) - directions, along) / np.linalg.norm(gap, axis=1)


def enveloped_cushion(
    contact: Contact, face: Face, warped: np.ndarray, cushion: Cushion, preload_mm: np.ndarray, wall: trimesh.Trimesh,
    fit_params: FitParams, awake: CushionFit, faces: dict[FaceState, Face] | None = None,
) -> tuple[Cushion, trimesh.Trimesh, tuple[float, float]]:
    """(the cushion with its membrane, its printable solid, (the membrane's thinnest wall mm, the
    least share of its set thickness)): the
    `cushion` (its `wall` solid pressed onto the face as `awake`, at the force the states keep)
    given the membrane the predicted states need (`with_flaps`). `faces`: the face in each sleep
    state where already made (`state_faces`)."""
    params = cushion.params
    states = fit_states({"custom": wall}, face, sleep_states(cushion.mask), params.flange_mm, awake.force_n, fit_params,
                        {"custom": awake}, faces=faces)
    need = column_need(needed_reach(states, awake, fit_params.cpap_kpa), awake.rim.points, contact)
    widths = flap_widths(need, contact, params.membrane_mm)
    return with_flaps(contact, face.axis, face.up, warped[NOSE_TIP], params, preload_mm, widths, face.registered, wall, need)


def with_flaps(
    contact: Contact, axis: np.ndarray, up: np.ndarray, nose_tip: np.ndarray, params: CushionParams, preload_mm: np.ndarray | None,
    widths: np.ndarray, skin: trimesh.Trimesh, wall: trimesh.Trimesh, need: dict[float, np.ndarray] | None = None,
) -> tuple[Cushion, trimesh.Trimesh, tuple[float, float]]:
    """(the cushion with its membrane, its printable solid, (the membrane's thinnest wall mm, the
    least share of its set thickness, `with_membrane`)): the design (`design_cushion` of these arguments) given flaps of
    `widths` (AROUND,) mm, its `wall` solid joined to them; narrowed where the membrane's sheet would
    twist (`twisted_columns`), and everywhere while its solid would cross itself (beyond the
    slivers `with_membrane` collapses), by SHRINK at most
    SHRINKS times each. `need` {CPAP kPa: (AROUND,) mm}: the reach each column's flap must have at
    each pressure; the flaps are then sized for this face: the neighbours of the columns each
    narrowing takes in step down to them (`tapered`), and where a flap as built (`built_widths`) is narrower than
    reaches its need, its sheet is thinner (`flap_thickness`). None (the stock family's flaps, modelled once): neither, and
    `params.membrane_mm` throughout."""
    def sized_for(widths: np.ndarray) -> Cushion:
        flaps = design_cushion(contact, axis, up, nose_tip, params, preload_mm, widths, skin)
        if need is None:
            return flaps
        return replace(flaps, membrane_thickness=flap_thickness(need, np.minimum(widths, built_widths(flaps)), params.membrane_mm))

    for _ in range(SHRINKS + 1):
        sized = sized_for(widths)
        twisted = twisted_columns(sized.membrane_grid())
        if not twisted.any():
            break
        widths = np.where(twisted, SHRINK * widths, widths)
        if need is not None:
            widths = np.minimum(widths, tapered(np.where(twisted, widths, np.inf)))
    for attempt in range(SHRINKS + 1):
        solid, thinnest, crossings = with_membrane(sized, wall, contact.normals)
        if crossings == 0 or attempt == SHRINKS:  # the cushion returned is the one its solid was made from
            break
        widths = SHRINK * widths
        sized = sized_for(widths)
    return sized, solid, thinnest


def built_widths(cushion: Cushion) -> np.ndarray:
    """(AROUND,) mm: how far each control column's flap, as built, reaches from the seal curve to its
    free edge in a straight line, as the evaluation reads a flap across its section (from the rim
    point, `membrane.rim_membrane`, which may lie across the flange from the seal curve): laid along
    skin that curves under it, shorter than the width asked; on flat skin a little longer (its free
    edge stands off the skin), which is why `with_flaps` takes the lesser."""
    reach = np.linalg.norm(cushion.membrane_grid(AROUND, 2)[:, -1] - cushion.grid(AROUND, 2)[:, 0], axis=1)
    return np.roll(reach, 1)  # grid point k lies on column k + 1 (`Cushion.membrane_thickness_at`)


def tapered(widths: np.ndarray) -> np.ndarray:
    """(AROUND,) mm: `widths` (AROUND,) mm around the closed seal curve lowered where needed so that
    no column stands more than TAPER_MM a column above another (each the least, over all columns
    itself included, of their width plus TAPER_MM per column between; inf widths impose nothing)."""
    steps = np.arange(len(widths))
    between = np.minimum(steps, len(widths) - steps)
    return np.min([np.roll(widths, k) + TAPER_MM * between[k] for k in steps], axis=0)


def twisted_columns(grid: np.ndarray) -> np.ndarray:
    """(AROUND,) bool: the control columns (and their neighbours, within the cubic's reach) where a
    membrane's (n_u, n_v, 3) sheet turns back on itself or closes up: a row's step around the seal
    against its root row's reversed or under CLOSING of it."""
    step = np.roll(grid, -1, axis=0) - grid  # (n_u, n_v, 3)
    root = step[:, :1]
    along = np.einsum("uvc,uvc->uv", step, np.broadcast_to(root, step.shape)) / np.maximum(np.einsum("uvc,uvc->uv", root, root), 1e-12)
    bad = np.flatnonzero((along[:, 1:] < CLOSING).any(axis=1))
    columns = np.zeros(AROUND, dtype=bool)
    # grid row k lies at column k AROUND / n_u + 1 (`Cushion.membrane_thickness_at`), in the span
    # between columns j + 1 and j + 2 (j = k AROUND // n_u) that the cubic's columns j..j + 3 shape
    for near in (0, 1, 2, 3):
        columns[(bad * AROUND // len(grid) + near) % AROUND] = True
    return columns
