"""Every JSON record cpapfit writes, built here from the stages' results, each with
SCHEMA_VERSION; the JSON Schema of each file is `cpapfit/schemas/<name>.schema.json`
(`schemas.schema`). All lengths mm, pressures kPa, forces N, flows L/min, in the scan's frame."""

import numpy as np

from . import __version__
from .fabrication.dead_space import CUSHION_SHARE
from .fabrication.draft import Draft
from .cushion.envelope import PEAK_MARGIN_KPA
from .evaluation.fe import SILICONE_KPA, SILICONE_POISSON
from .evaluation.fit import FitParams
from .evaluation.leak import AIR_DENSITY_KG_M3, AIR_VISCOSITY_PA_S, DISCHARGE_COEFFICIENT
from .evaluation.membrane import BAND_MM, LARGE, LIFT, MEMBRANE_MAX_MM, ROOT_MM, ROOT_SHARE
from .evaluation.states import AWAKE
from .fabrication.frame import BORE_MM, CONE_MM, CONE_TAPER, GAUGE_PLANE_MM, VALVE_MM, cone_diameter_mm
from .io.landmarks import landmarks_record
from .align.nonrigid import Registration
from .pipeline import Alignment, Design
from .scan import Scan
from .schemas import SCHEMA_VERSION
from .stock_fit import StockComparison
from .template import load_template
from .thresholds import DEAD_SPACE_LIMIT_ML, MAX_BELOW_MIN, MAX_UNDERCUT, MIN_DRAFT_DEG


def mask_dimensions(d: Design) -> dict:
    """Width (across the face), height (along the head) and depth (along the mask axis) in mm."""
    axis, up = d.cushion.axis, d.cushion.up
    side = np.cross(up, axis)
    v = d.solid.vertices
    return {f"{k}_mm": round(float(np.ptp(v @ a)), 2) for k, a in (("width", side), ("height", up), ("depth", axis))}


def mould_record(drafts: dict) -> dict:
    """The casting mould's part of fit.json: each part's demoulding draft, and what it means."""
    return {
        **{name: d.record() | {"left": _left(d)} for name, d in drafts.items()},
        "draft_about": f"draft of each part's moulding surface along its pull direction; below {MIN_DRAFT_DEG:g} deg it drags, "
                       f"below 0 it is an undercut. Target: at most {MAX_UNDERCUT:.0%} of a part's moulding area undercut and at "
                       f"most {MAX_BELOW_MIN:.0%} under {MIN_DRAFT_DEG:g} deg (meets_target); the outer parts are split so that "
                       "each takes the surface it faces, the core is one piece drawn through one opening",
    }


def _left(d: Draft) -> str:
    """What a mould part's draft leaves to the silicone, in words."""
    shares = (f"{d.undercut_fraction:.1%} of its moulding area undercut (down to {d.min_draft_deg:.0f} deg), "
              f"{d.below_min_fraction:.1%} under {MIN_DRAFT_DEG:g} deg")
    if d.meets_target:
        return f"within the target: {shares}"
    return f"{shares}: it comes out only as the cured silicone flexes and stretches off it"


def evaluation_record(fits: dict, params: FitParams) -> dict:
    """The evaluate stage's part of fit.json: the custom cushion at its headgear force,
    each other cushion (generic, stock) at its own (its `headgear_force_n`)."""
    custom = fits["custom"]
    return {
        "cpap_cmh2o": params.cpap_cmh2o,
        "headgear_force_n": round(custom.force_n, 3),
        "headgear_force_about": "the custom cushion's: the force asked for (evaluate --force), else the recommended force (at "
                                "which a cushion compensated for this face presses every covered rim point with the target pressure "
                                "while balancing the CPAP load); where the sleep states are pressed (design, evaluate --states), "
                                "the larger of that and the least force that seals the awake face and each state at this CPAP "
                                f"pressure, held to the force at which the awake peak comes {PEAK_MARGIN_KPA:g} kPa under capillary "
                                "closing (never below the awake seal force), then raised within that limit to the least force (of 16 "
                                "steps) that keeps the most of the rim in the safe window (cpapfit.cushion.envelope); "
                                "a stock cushion at the force a clinic sets for it (stock_fitting)",
        "window": params.describe(),
        **{name: fit.summary() for name, fit in fits.items()},
        "tissue_model": params.tissue.describe(),
        "mechanics": {
            "model": "rigid mask on an elastic foundation; equilibrium of force along the mask axis and moments across it; "
                     "contact band = seal flange width; gaps and indentations along the axis, pressures normal to the skin",
            "contact_width_mm": custom.contact_width_mm,
            "pressure_stats_over": "rim points over scanned skin (rim_covered_fraction of the rim); zero where not in contact",
        },
        "leak_model": {
            "model": "seal open where contact pressure < CPAP pressure, opening (P - p) / k; flow = min(lubrication h^3 dP ds / "
                     "(12 mu L), orifice Cd h ds sqrt(2 dP / rho)), L = seal flange width",
            "air_viscosity_pa_s": AIR_VISCOSITY_PA_S, "air_density_kg_m3": AIR_DENSITY_KG_M3, "discharge_coefficient": DISCHARGE_COEFFICIENT,
        },
        "membrane_model": {
            "model": "a flap thinner than the wall (found on the cushion mesh by its thickness) closes the seal opening at a rim "
                     "point up to its reach, the largest opening at which the CPAP pressure still lays it band_mm on the skin: "
                     "d (1 - large d / a) - lift a / 3 - root_mm, d = P a^4 / (72 D), a = w - band_mm + t, D = E t^3 / (12 (1 - nu^2)) "
                     "(the clamped plate laid on the skin, fitted to finite elements), at most w - band_mm; none where the mask lifts off. "
                     "Where its wall stands at the skin or off it (easing to none pressed root_mm in), a flap's root pulls the wall "
                     "towards the skin by root_share of the air's push on the span a it bridges to where it lies at no opening "
                     "(root_share P a, per mm of rim, fitted to finite elements) while it closes the opening there, so the "
                     "headgear holds the CPAP load less those pulls",
            "band_mm": BAND_MM, "large": LARGE, "lift": LIFT, "root_mm": ROOT_MM, "root_share": ROOT_SHARE,
            "max_thickness_mm": MEMBRANE_MAX_MM, "youngs_kpa": SILICONE_KPA, "poisson": SILICONE_POISSON,
        },
    }


STATE_KEYS = ("leak_l_min", "window_fraction", "pressure_max_kpa", "pressure_max_region", "seal_force_n", "headgear_force_n",
              "rim_covered_fraction", "lifted_off")


def states_record(fits: dict, states: tuple, cpap_cmh2o: float) -> list[dict]:
    """fit.json's `states`: awake (the `fits`) and each `StateFit`, every cushion's leak, window,
    peak pressure and where, each at its awake headgear force (`cpap_cmh2o`: the awake pressure)."""
    rows = [(AWAKE, fits, "")] + [(s.state, s.fits, s.error) for s in states]
    return [_state_row(state, by_cushion, error, cpap_cmh2o) for state, by_cushion, error in rows]


def _state_row(state, fits: dict, error: str, cpap_cmh2o: float) -> dict:
    """One state's row of fit.json's `states`."""
    row = {"name": state.name, "parameters": state.parameters(cpap_cmh2o)}
    row |= {name: {k: v for k, v in fit.summary().items() if k in STATE_KEYS} for name, fit in fits.items()}
    return row | ({"error": error} if error else {})


def other_start(reg: Registration, mask: str) -> dict:
    """The registration against the run that weighs less in it: `start_product` (`Registration.start_product`)
    and `other_start_band_mm`, the mean distance (mm) between the `mask` contact bands of the
    registration and of the run that weighs less in it (both null with one start; the product null
    where the morphable run found no pairs)."""
    if reg.other_run is None:
        return {"start_product": None, "other_start_band_mm": None}
    apart = reg.other_run_apart_mm(load_template().regions[mask].band)
    product = round(float(reg.start_product), 4) if np.isfinite(reg.start_product) else None  # a run without pairs
    return {"start_product": product, "other_start_band_mm": round(apart, 3)}


def design_record(d: Design, scan: Scan) -> dict:
    """fit.json of `cpapfit design`."""
    reg = d.registration
    return {
        "schema_version": SCHEMA_VERSION,
        "cpapfit_version": __version__, "units": "mm", "source": scan.source, "scan_units": scan.units,
        "mask": d.contact.mask,
        **d.quality.record(),  # rescan_advised, warnings, quality
        "landmarks": {"path": d.alignment.landmarks.path, "count": len(d.alignment.landmarks.points), "note": d.alignment.landmarks.note,
                      "rejected": d.alignment.landmarks.rejected},
        "registration": {"iterations": len(reg.log), "matched_vertices": int(reg.valid.sum()),
                         "residual_median_mm": float(np.median(reg.residual[reg.valid])),
                         "landmark_weight_factor": reg.landmark_factor, "start": reg.start,
                         "morphable_share": round(reg.morphable_share, 4), "bending_mm2": round(reg.bending, 3),
                         "landmark_spread_mm": None if np.isnan(reg.landmark_spread_mm) else round(reg.landmark_spread_mm, 3),
                         **other_start(reg, d.contact.mask)},
        "seal_on_scan_fraction": float(d.contact.on_scan.mean()),
        "cushion": {**mask_dimensions(d), **d.checks},
        "fit_before_compression": d.rim.summary(),
        "mould": mould_record(d.mould_draft),
        "pressure_compensation": {
            "target_kpa": d.fit_params.target_kpa,
            "preload_mm": {k: round(float(f(d.preload.mm)), 3) for k, f in (("min", np.min), ("median", np.median), ("max", np.max))},
            "preload_smoothing_samples": d.preload.smoothing,
            "about": "the rim is set into the skin along the mask axis by more where the tissue is soft, so that at the "
                     "recommended headgear force it presses evenly",
        },
        **evaluation_record(d.fits, d.fit_params),
        "states": states_record(d.fits, d.states, d.fit_params.cpap_cmh2o),
        **({"stock_fitting": d.stock.record()} if d.stock else {}),
        **({"stock_not_fitted": d.stock_not_fitted} if d.stock_not_fitted else {}),
        "states_about": "the face asleep (`cpapfit.evaluation.states`): lying on the back with the jaw dropped (the ICT model's "
                        "jawOpen carried onto this face), the mask pushed across its axis or rolled by a pillow, the CPAP "
                        "range's ends; each cushion at its awake headgear force; the custom cushion's membrane is sized so that "
                        "it seals in each (`cpapfit.cushion.envelope`); stock: the best stock size as a clinic fits it (stock_fitting)",
        "parameters": dict(vars(d.cushion.params)),
    }


def evaluate_record(scan: Scan, cushion_file: str, fits: dict, params: FitParams, stock: StockComparison | None,
                    states: tuple | None) -> dict:
    """fit.json of `cpapfit evaluate`: the cushion in `cushion_file` (and any compared) pressed onto `scan`."""
    record = {"schema_version": SCHEMA_VERSION, "cpapfit_version": __version__, "units": "mm", "source": scan.source,
              "scan_units": scan.units, "cushion_file": cushion_file, **evaluation_record(fits, params)}
    record |= {"stock_fitting": stock.record()} if stock else {}
    return record | ({"states": states_record(fits, states, params.cpap_cmh2o)} if states is not None else {})


def _mm(points) -> list:
    return np.round(np.asarray(points, dtype=float), 3).tolist()


def mask_record(d: Design) -> dict:
    """mask.json: the assembled mask: the frame's connector, vents, valve, headgear anchors, the dead
    space, how the cushion sits in the frame, materials and print notes (mm, scan frame)."""
    f = d.frame
    return {
        "schema_version": SCHEMA_VERSION, "cpapfit_version": __version__, "units": "mm", "mask": d.contact.mask,
        "parts": {"cushion": "cushion.stl", "frame": "frame.stl", "assembly": "assembly.3mf"},
        "port": {
            "standard": "ISO 5356-1 22 mm male conical connector", "tip_mm": _mm(f.port_tip), "axis": _mm(f.port_axis),
            "tip_diameter_mm": float(cone_diameter_mm(0.0)), "gauge_plane_from_tip_mm": GAUGE_PLANE_MM,
            "gauge_diameter_mm": round(float(cone_diameter_mm(GAUGE_PLANE_MM)), 4), "taper_on_diameter": CONE_TAPER,
            "cone_length_mm": CONE_MM, "bore_mm": BORE_MM,
            "about": "axis along the mask axis, out of the face; the cone's diameter is tip_diameter_mm + taper_on_diameter x "
                     "the distance from the tip, up to a shoulder at cone_length_mm",
        },
        "vents": f.vents.record() | {"holes": [{"centre_mm": _mm(p), "direction": _mm(v)} for p, v in f.vent_holes],
                                     "placed": "rows across the frame's dome within 35 deg of the head's up direction, each "
                                               "hole along the dome's outward normal: away from the face and from a bed partner"},
        "valve": None if f.valve is None else {
            "centre_mm": _mm(f.valve[0]), "direction": _mm(f.valve[1]), "opening_mm": VALVE_MM[0], "seat_mm": VALVE_MM[1],
            "seat_height_mm": VALVE_MM[2],
            "about": "anti-asphyxia valve: the opening in the dome's lower side with a flat ring inside it for the flap's seat; "
                     "the flap (not made here) closes on the seat under CPAP pressure and falls open without it",
        },
        "headgear": {
            "anchors_mm": _mm(f.anchors),
            "about": "four strap slots placed symmetrically about the mask axis (upper and lower pairs at 35 deg from the "
                     "across-the-face direction): with equal strap tensions at mirror angles their resultant lies along the mask "
                     "axis through the seal's centre, as the fit model assumes; unequal tensions, or a strap path not mirrored "
                     "(a forehead strap higher than the lower straps are low), tilt the mask, which the model does not cover",
        },
        "dead_space_ml": round(d.dead_space_ml, 2), "dead_space_limit_ml": DEAD_SPACE_LIMIT_ML[d.contact.mask],
        "dead_space_within_limit": bool(d.dead_space_ml <= DEAD_SPACE_LIMIT_ML[d.contact.mask]),
        "ring_clearance_mm": round(float(d.cushion.params.frame_clearance_mm), 3),
        "dead_space_about": "air between the face (the registered template inside the seal) and the connector's bore: the "
                            "cushion's inside and the frame's less the frame's solid, in columns along the mask axis; the frame "
                            "ring stands ring_clearance_mm over the nose tip, lowered from the cushion's setting where the "
                            f"cushion's inside would take more than {100 * CUSHION_SHARE:.0f} % of the limit (a large face)",
        "assembly": f.assembly,
        "frame": d.frame_checks,
        "materials": {
            "frame": "a rigid biocompatible (ISO 10993 tested) material: a medical SLA resin, or PA12 nylon by SLS",
            "cushion": "medical-grade (ISO 10993 tested) silicone, cast in the mould (mould_*.stl)",
        },
        "print_notes": [
            "print the frame with the connector's axis vertical, port up, so that the cone is round and free of supports",
            "check the cone with an ISO 5356-1 22 mm ring gauge before use; the vent holes (1.2 mm) must be open: clear "
            "them with a 1.2 mm drill if the printer closes them",
            "keep supports out of the groove that takes the cushion's end; the cushion's end is pressed into it all round",
        ],
    }


def contact_curve_record(d: Design) -> dict:
    """contact_curve.json: the seal curve, a closed loop in order."""
    return {"schema_version": SCHEMA_VERSION, "units": "mm", "mask": d.contact.mask, "points": np.round(d.contact.curve, 4).tolist()}


def landmarks_file_record(al: Alignment, scan: Scan) -> dict:
    """The landmarks file of `cpapfit landmarks`: the landmarks a design would use, the similarity and the face check."""
    fit, check = al.similarity, al.check
    return {"schema_version": SCHEMA_VERSION, **landmarks_record(al.landmarks),
            "similarity": {"scale": fit.scale, "rotation": fit.rotation.tolist(), "translation_mm": fit.translation.tolist(),
                           "landmark_rms_mm": fit.rms_mm, "note": "template (mm) -> scan (mm): x -> scale * R x + t"},
            "face_check": {"coverage": check.coverage, "median_gap_mm": check.median_gap_mm, "nose_above_sides_mm": check.ridge_mm,
                           "nose_above_lip_mm": check.below_mm,
                           "turned_from_camera_deg": None if np.isnan(check.turned_deg) else check.turned_deg},
            "source": scan.source, "scan_units": scan.units}


def manifest_record(task, files: tuple, landmarks: str | None, stamp: dict) -> dict:
    """manifest.json of a design folder: the scan and settings of its `jobs.ScanTask`, the files
    written, the landmarks file given (and a batch's `stamp`)."""
    return {"schema_version": SCHEMA_VERSION, "cpapfit_version": __version__, "scan": str(task.scan), "files": list(files),
            "parameters": {"mask": task.mask, "units": task.units, "stock": task.stock, "landmarks": landmarks}, **stamp}
