"""A stock cushion fitted as a clinic fits one: sized by the gauge or by trying each size, seated
on the nasal bridge and slid across the mask axis to where it seals best, the headgear tightened
until it seals (and MARGIN more), up to COMFORT_N.

Seating: the stock cushion (`cushion.stock`, template frame) is turned into the face's frame (its
axis and up) and put with its nasal-bridge point on the registered template's; then moved across
the axis on a 3 x 3 grid SEAT_STEPS_MM[0] apart and again SEAT_STEPS_MM[1] apart around the best
(17 seats; a compass walk from the bridge tries fewer but settles on worse seats, `bench/RESULTS.md`).
A seat that seals at no more than COMFORT_N is better than one that does not; among those that seal, the lower peak pressure
at the force that seals them is better; among those that do not, the lower leak at COMFORT_N.
The best size is the best seat of every size so judged. A seat from which the cushion's wall does not
run all the way round the mask axis over the scanned face is no seat; a size with none is not fitted there.
"""

from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Callable

import numpy as np
import trimesh

from .cushion.nurbs import CushionParams
from .cushion.population import gauge_mm
from .cushion.stock import BRIDGE, SIZES, mean_face, size_scale, stock_solid
from .errors import InputError, NoStockSeat
from .evaluation.fit import CushionFit, Face, FitParams, at_force, fit_rim
from .evaluation.rim import RimZone, in_plane, refined, rim_in, rim_zone
from .evaluation.states import FaceState, StateFit, fit_states, merged, sleep_states
from .work import Again, Shared, at_once

COMFORT_N = 10.0  # the most headgear force a clinic sets for comfort
MARGIN = 1.1  # the straps are set this much above the force that just seals
SEAT_STEPS_MM = (2.0, 1.0)
GRID = np.stack(np.meshgrid([-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]), axis=-1).reshape(-1, 2)


@dataclass(frozen=True)
class StockFit:
    """A stock size seated on a face: `size`, `offset_mm` (2,) its seat across the axis from the
    nasal bridge (side towards the patient's left, up), `fit` pressed at the force the clinic sets,
    `sealed` whether that force (at most COMFORT_N) closes the seal."""

    size: str
    offset_mm: tuple
    fit: CushionFit
    sealed: bool

    def record(self) -> dict:
        """Its seat, force and whether it sealed within COMFORT_N, for fit.json."""
        return {"seat_offset_mm": [round(float(v), 3) for v in self.offset_mm], "headgear_force_n": round(self.fit.force_n, 3),
                "sealed_within_comfort": self.sealed}

    def rank(self) -> tuple:
        """Smaller is better: sealed first, then the peak pressure (sealed) or the leak (not)."""
        s = self.fit.summary()
        return (0, s["pressure_max_kpa"]) if self.sealed else (1, s["leak_l_min"])


@dataclass(frozen=True)
class StockComparison:
    """The stock cushion a clinic would fit on a face, to set beside the custom one: the sizes
    tried, each at its best seat (`sizes`, best first), the size the gauge picks, and the best size
    pressed in each sleep state (`sleep_states`) at the force the clinic set for it (or none), and
    the gauge's size too where it was tried and is not the best (`gauge_states`, else none); the
    sizes tried that found no seat on the face (`not_seated`)."""

    sizes: tuple[StockFit, ...]
    gauge: str
    states: tuple[StateFit, ...]
    gauge_states: tuple[StateFit, ...] = ()
    not_seated: tuple[str, ...] = ()

    @property
    def best(self) -> StockFit:
        return self.sizes[0]

    @property
    def gauge_fit(self) -> StockFit | None:
        """The gauge's size, where it was tried and is not the best."""
        return next((f for f in self.sizes[1:] if f.size == self.gauge), None)

    @property
    def fits(self) -> dict[str, CushionFit]:
        """The awake fits to set beside the custom cushion's: "stock" the best size, "stock_gauge" the gauge's."""
        gauge = self.gauge_fit
        return {"stock": self.best.fit} | ({"stock_gauge": gauge.fit} if gauge else {})

    def beside(self, states: tuple[StateFit, ...]) -> tuple[StateFit, ...]:
        """Each of `states` (the same sleep states, other cushions) with this comparison's fits in it."""
        out = tuple(map(merged, states, self.states))
        return tuple(map(merged, out, self.gauge_states)) if self.gauge_states else out

    def record(self) -> dict:
        """fit.json's `stock_fitting`: how the best size was fitted, and every size tried."""
        tried = {f.size: f.record() | {k: f.fit.summary()[k] for k in SIZE_KEYS} for f in self.sizes}
        return {"size": self.best.size, "gauge_size": self.gauge, **self.best.record(), "comfort_max_n": COMFORT_N,
                "fitted": "seated on the nasal bridge and slid across the mask axis to its best seat; the headgear set "
                          f"{MARGIN:g} times the force that seals it, at most the comfort maximum",
                "sizes_best_first": tried, "not_seated": list(self.not_seated)}


SIZE_KEYS = ("leak_l_min", "window_fraction", "pressure_max_kpa", "pressure_max_region")


@dataclass(frozen=True)
class StockFitting:
    """Stock sizes being seated on `face` by `submit` (`work.py`: a worker process's, or at once),
    one at a time, while other work goes on; `comparison` gathers them, seating here, from the
    last, the sizes the worker has not been handed yet (`work.Shared`)."""

    mask: str
    face: Face
    gauge: str  # the size the gauge picks for this face
    sizes: tuple[str, ...]  # in SIZES order
    seats: Shared  # each size's StockFit (or None), being made
    params: CushionParams
    fit_params: FitParams
    submit: Callable

    def comparison(self, asleep: bool = True, faces: dict[FaceState, Face] | None = None,
                   meanwhile: Callable[[], None] = lambda: None) -> StockComparison:
        """The `StockComparison`; `asleep`: the best size (and the gauge's) pressed in each sleep state
        too, on `faces` where already made (`state_faces`: the custom cushion's, on a mesh scan
        hundreds of MB each; the gauge's size, pressed by a worker, on faces of its own).
        `meanwhile()` is called once the sizes are seated and the gauge's states handed out, before
        the best's are pressed here: work to hand the worker, which would otherwise wait."""
        mask, face, params, fit_params = self.mask, self.face, self.params, self.fit_params
        done = dict(zip(self.sizes, self.seats.results()))
        sizes = tuple(sorted((fit for fit in done.values() if fit is not None), key=StockFit.rank))
        if not sizes:
            raise NoStockSeat(f"no {mask} stock size tried ({', '.join(self.sizes)}) finds its rim over "
                             "this face at any seat: its wall does not run all the way round the mask axis over the face, "
                             "or lies over too little scanned skin")
        compared = StockComparison(sizes, self.gauge, (), not_seated=tuple(size for size, fit in done.items() if fit is None))
        gauge_fit = compared.gauge_fit
        if not asleep:
            return compared
        here = faces if self.submit is at_once else None  # a worker makes its own, sharing their triangles as this process's do
        gauge_states = self.submit(stock_states, mask, gauge_fit, face, params, fit_params, "stock_gauge", here) if gauge_fit else None
        meanwhile()
        return replace(compared, states=stock_states(mask, sizes[0], face, params, fit_params, faces=faces),
                       gauge_states=gauge_states.result() if gauge_states else ())


def fitting_stock(mask: str, face: Face, choice: str = "best", params: CushionParams = CushionParams(),
                  fit_params: FitParams = FitParams(), submit: Callable = at_once) -> StockFitting:
    """The stock cushion of `mask` a clinic would fit on `face`, being seated: `choice` a size,
    "gauge" (the size the gauge picks) or "best" (every size, the best kept)."""
    gauge = gauge_size(mask, np.asarray(face.registered.vertices))
    sizes = SIZES[mask] if choice == "best" else (gauge if choice == "gauge" else choice,)
    seats = Shared(submit, seat_step, [(mask, size, face, params, fit_params) for size in sizes])
    return StockFitting(mask, face, gauge, tuple(sizes), seats, params, fit_params, submit)


def compared_stock(mask: str, face: Face, choice: str = "best", params: CushionParams = CushionParams(),
                   fit_params: FitParams = FitParams(), asleep: bool = True) -> StockComparison:
    """`fitting_stock` here and now, gathered: the stock cushion of `mask` a clinic would fit on
    `face`; `asleep`: pressed in each sleep state too."""
    return fitting_stock(mask, face, choice, params, fit_params).comparison(asleep)


def stock_states(mask: str, fit: StockFit, face: Face, params: CushionParams = CushionParams(),
                 fit_params: FitParams = FitParams(), name: str = "stock",
                 faces: dict[FaceState, Face] | None = None) -> tuple[StateFit, ...]:
    """The stock cushion of `fit` in each sleep state of `mask` on `face`, at the force set for it,
    as `name`; `faces`: the face in each state where already made (`state_faces`)."""
    mesh, thickness = placed_stock(mask, fit, face, params)
    return fit_states({name: mesh}, face, sleep_states(mask), params.flange_mm, fit.fit.force_n, fit_params,
                      {name: fit.fit}, {name: thickness}, faces)


def gauge_size(mask: str, registered: np.ndarray) -> str:
    """The size (S, M or L) whose gauge measure lies nearest the face's, from its registered template (N, 3) mm."""
    measure, mean = gauge_mm(mask, registered), gauge_mm(mask, mean_face())
    return min(("S", "M", "L"), key=lambda s: abs(measure - mean * size_scale(mask, s)[0]))


def seated(mask: str, size: str, face: Face, params: CushionParams = CushionParams(),
           fit_params: FitParams = FitParams()) -> StockFit | None:
    """The stock `size` at its best seat on `face` (module docstring); None where at no seat tried
    is its rim found (`rim_in`: its wall does not run all the way round the mask axis over the face,
    as a size too large for it, or lies over too little scanned skin). Each of SEAT_STEPS_MM is a
    `seat_step`."""
    found = seat_step(mask, size, face, params, fit_params)
    while isinstance(found, Again):
        found = seat_step(mask, size, face, params, fit_params, *found.args)
    return found


def seat_step(mask: str, size: str, face: Face, params: CushionParams, fit_params: FitParams, zone: RimZone | None = None,
              steps: tuple[float, ...] = SEAT_STEPS_MM, best: StockFit | None = None) -> StockFit | None | Again:
    """One step of `seated`: the seats of the grid steps[0] mm apart about the best seat so far
    (`best`, not pressed again; the nasal bridge to begin), then, while steps remain, the next step
    as `Again` (`work.Shared` hands it to whichever process is free); else the best seat (None
    where none found its rim). `zone`: the size's `RimZone` on the nasal bridge (made here to begin)."""
    if zone is None:
        mesh, thickness = _refined_stock(mask, size, params)
        zone = rim_zone(_placed(mesh, face, np.zeros(2)), face.axis, face.up, thickness)  # every seat's, moved across the axis
    centre = np.zeros(2) if best is None else np.asarray(best.offset_mm)
    grid = centre + steps[0] * GRID
    for offset in grid if best is None else grid[(grid != centre).any(axis=1)]:
        trial = _seat(size, zone, face, offset, params, fit_params)
        if trial is not None and (best is None or trial.rank() < best.rank()):
            best = trial
    if best is None or len(steps) == 1:
        return best
    return Again((zone, steps[1:], best))


def _seat(size: str, zone: RimZone, face: Face, offset: np.ndarray, params: CushionParams, fit_params: FitParams) -> StockFit | None:
    """`_pressed`, or None where no rim over the face is found from this seat."""
    try:
        return _pressed(size, zone, face, offset, params, fit_params)
    except InputError:
        return None


def stock_solids(mask: str, choice: str = "best", params: CushionParams = CushionParams()) -> None:
    """Make (and cache in this process) the refined stock solids `fitting_stock` of `choice` seats;
    they depend on no face, so a worker can make them while the template is placed."""
    for size in SIZES[mask] if choice in ("best", "gauge") else (choice,):
        _refined_stock(mask, size, params)


@lru_cache(maxsize=8)
def _refined_stock(mask: str, size: str, params: CushionParams) -> tuple[trimesh.Trimesh, np.ndarray]:
    """The stock solid refined for finding its rim, and its vertices' thickness (`rim.refined`)."""
    return refined(stock_solid(mask, size, params))


def placed_stock(mask: str, fit: StockFit, face: Face, params: CushionParams = CushionParams()) -> tuple[trimesh.Trimesh, np.ndarray]:
    """(the stock cushion of `fit`, refined, in its seat on `face` (mm, scan frame); its vertices'
    thickness, mm: what `find_rim` takes for a refined cushion)."""
    mesh, thickness = _refined_stock(mask, fit.size, params)
    return _placed(mesh, face, np.asarray(fit.offset_mm)), thickness


def _placed(mesh: trimesh.Trimesh, face: Face, offset: np.ndarray) -> trimesh.Trimesh:
    """A stock `mesh` (template frame) turned into the face's frame, its nasal bridge on the face's
    moved `offset` (2,) mm across the axis (side, up)."""
    side, up = in_plane(face.axis, face.up)
    turn = np.column_stack([side, up, face.axis])
    bridge = np.asarray(face.registered.vertices)[BRIDGE] + offset @ np.stack([side, up])
    return trimesh.Trimesh((mesh.vertices - mean_face()[BRIDGE]) @ turn.T + bridge, mesh.faces, process=False)


def _pressed(size, zone: RimZone, face: Face, offset, params: CushionParams, fit_params: FitParams) -> StockFit:
    """The stock `size` (`zone`: its `RimZone` seated on the face's nasal bridge) moved `offset` (2,) mm and pressed."""
    across = trimesh.transformations.translation_matrix(np.asarray(offset) @ in_plane(face.axis, face.up))
    rim = rim_in(zone.moved(across), face.scan, face.registered, face.axis, face.up)
    at_most = fit_rim(rim, face, params.flange_mm, COMFORT_N, fit_params)
    seal = at_most.seal_force_n
    if seal is None or seal * MARGIN > COMFORT_N:
        return StockFit(size, tuple(offset), at_most, False)
    return StockFit(size, tuple(offset), at_force(at_most, seal * MARGIN, fit_params), True)
