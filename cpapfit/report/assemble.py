"""The report of a design as files: the pictures (PNG) and report.html, from the design, the
scan, the fit.json and mask.json records and, once evaluated, each cushion's rim pressure.

Pure: the caller (cpapfit/outputs.py) supplies what comes from outside (input hash, date) and,
optionally, a worker process (`work.py`) that draws four of the design's pictures meanwhile
(`design_pictures`)."""

from dataclasses import dataclass

import numpy as np
from matplotlib import colormaps

from .. import __version__
from ..align.nonrigid import Registration
from ..cushion.contact import Contact
from ..evaluation.fit import CushionFit
from ..memory import release
from ..pipeline import Alignment, Design
from ..render import Scene, scene_of
from ..scan import Scan
from ..similarity import Similarity
from ..template import load_template
from ..work import at_once
from . import pictures as pic
from .advice import at_seal_force, fit_notices, gate_notices, landmark_notices, scan_notices
from .figure import ColourScale, zoned_cmap
from .frame import Face, seal_view, shoot, whole_face_view
from .page import Page, Picture, lookup, report_html
from ..loops import loop_lengths
from .rim import RimFit
from .viewer import viewer_face, viewer_figure, viewer_html

GAP_SCALE = ColourScale(colormaps["plasma"], 0.0, 3.0, "gap between rim and skin (mm)", ((1.0, "1 mm"),))
RIM_SAMPLES = 256


@dataclass(frozen=True)
class Provenance:
    """Where a report comes from: input path and its SHA-256, the run date (text), the command's settings."""

    source: str
    sha256: str
    date: str


def evaluated_rims(d: Design) -> dict:
    """{"custom" | "stock": RimFit} from the design's evaluation: the rim's place on the skin, the gap
    before load (the custom one's without its pre-load, i.e. its shape's fit), pressure and openings.
    The pictures set the custom cushion beside the best stock size; the gauge's size is in the tables."""
    return {name: rim_fit(fit, d.preload_at(fit.rim.points) if name == "custom" else 0.0)
            for name, fit in d.fits.items() if name != "stock_gauge"}


def rim_fit(fit: CushionFit, preload_mm: np.ndarray | float = 0.0) -> RimFit:
    """A `CushionFit`'s rim as the pictures show it: on the skin where covered, its gap before load
    less `preload_mm` (K,) (or one number), pressure and openings."""
    rim, c = fit.rim, fit.rim.covered
    clearance = rim.clearance + preload_mm
    where = np.where(c[:, None], rim.skin, rim.points)
    return RimFit(where, clearance - np.nanmin(clearance[c]), fit.pressure_kpa, np.nan_to_num(fit.opening_mm) > 0)


def state_picture(shot, d: Design, scale: ColourScale) -> Picture:
    """The custom cushion's rim pressure and openings in each state of the sleeping face, on the awake face."""
    fits = {"awake": d.fits["custom"]} | {s.state.name: s.fits["custom"] for s in d.states if "custom" in s.fits}
    rims = {n: rim_fit(fit) for n, fit in fits.items()}
    summaries = {n: fit.summary() for n, fit in fits.items()}
    titles = {n: f"{n}: lifted off by the CPAP load" if fits[n].pressed.lifted else
              f"{n}: leak {s['leak_l_min']:.1f} L/min, peak {s['pressure_max_kpa']:.1f} kPa" for n, s in summaries.items()}
    arrays = {n: (r.points, np.asarray(r.pressure_kpa), np.asarray(r.open, dtype=bool)) for n, r in rims.items()}
    return Picture("states_pressure.png", "The custom cushion asleep",
                   "The custom cushion's contact pressure in each state of the sleeping face (lying on the back with the mouth open, the mask pushed "
                   "sideways or rolled by a pillow, the CPAP range's ends), at the headgear force set awake; drawn on the "
                   "awake face, near-black where the seal opens. The table above gives each state's numbers.",
                   pic.rim_map_picture(shot, arrays, scale, titles, "Contact pressure along the rim, each state", columns=4))


def scan_face(scan: Scan, d: Design) -> Face:
    """The surface the pictures show: the scan as it is seen (`Scan.seen`) with its colours, or the
    registered template for a point cloud."""
    if scan.is_point_cloud:
        return Face(d.registration.vertices, load_template().faces)
    seen = scan.seen
    return Face(seen.vertices, seen.faces, None if seen.colors is None else seen.colors / 255.0)


def pressure_scale(rims: dict, window_kpa: tuple) -> ColourScale:
    """Blue below the window, green in it, red above, up to 1.5 times its top or the highest pressure."""
    lo, hi = window_kpa
    top = np.ceil(2.0 * max(1.5 * hi, *(float(np.nanmax(r.pressure_kpa)) for r in rims.values()))) / 2.0
    return ColourScale(zoned_cmap(lo / top, hi / top), 0.0, top, "contact pressure (kPa)",
                       ((lo, f"seal {lo:.1f}"), (hi, f"limit {hi:.1f}")))


def gap_pictures(shot, similarity, mask: str, rims: dict, fit: dict) -> list[Picture]:
    """The seated gaps along both rims: map and profile."""
    titles = {n: f"{n}: gap median {np.nanmedian(r.gap_mm):.1f} mm, {100 * np.nanmean(r.gap_mm > 1.0):.0f} % over 1 mm" for n, r in rims.items()}
    arrays = {n: (r.points, r.gap_mm, None) for n, r in rims.items()}
    return [
        Picture("rim_gap.png", f"Gap under the rim, {' vs '.join(rims)}",
                "Each cushion pushed onto the face as a rigid body until its rim first touches the skin; colour: the gap left "
                "between rim and skin (the custom cushion's shape, before its pressure-compensating pre-load). Before the skin "
                "gives, so larger gaps mean more headgear force to close them.",
                pic.rim_map_picture(shot, arrays, GAP_SCALE, titles, "Gap between rim and skin (rigid, before compression)")),
        Picture("rim_gap_profile.png", "Gap along the rim",
                "The same gaps along the seal, starting at the nasal bridge and going round clockwise as seen from the front.",
                pic.profile_picture(similarity, mask, arrays, "gap between rim and skin (mm)", "Gap along the rim")),
    ]


def pressure_pictures(shot, similarity, mask: str, rims: dict, window_kpa: tuple, fit: dict) -> list[Picture]:
    """Contact pressure maps, pressure along the rim, and leak locations, of each rim of `rims`."""
    scale = pressure_scale(rims, window_kpa)
    arrays = {n: (r.points, np.asarray(r.pressure_kpa), np.asarray(r.open, dtype=bool)) for n, r in rims.items()}
    in_window = {n: f"{n}: {100 * (lookup(fit, f'{n}.window_fraction') or 0):.0f} % of the rim in the window, "
                    f"peak {float(np.nanmax(r.pressure_kpa)):.1f} kPa" for n, r in rims.items()}
    leaks = {n: f"{n}: open over {loop_lengths(r.points)[np.asarray(r.open, dtype=bool)].sum():.0f} mm of rim"
                + (f", leak {lookup(fit, f'{n}.leak_l_min'):.2f} L/min" if lookup(fit, f"{n}.leak_l_min") is not None else "")
             for n, r in rims.items()}
    lo, hi = window_kpa
    return [
        Picture("rim_pressure.png", f"Contact pressure on the rim, {' vs '.join(rims)}",
                f"Green: inside the safe window ({lo:.1f}-{hi:.1f} kPa: enough to seal against the CPAP pressure, below the "
                "pressure that closes skin capillaries); blue: too little to seal reliably; orange to red: above the limit, "
                "risk of pressure sores; near-black: no contact.",
                pic.rim_map_picture(shot, arrays, scale, in_window, "Contact pressure along the rim")),
        Picture("rim_pressure_profile.png", "Pressure along the rim",
                "Contact pressure along the seal from the nasal bridge, clockwise as seen from the front; the green band is the safe window.",
                pic.profile_picture(similarity, mask, arrays, "contact pressure (kPa)", "Contact pressure along the rim", window_kpa, mmhg=True)),
        Picture("leak.png", "Where the seal would leak",
                "Red: the rim does not touch the skin at the set headgear force, so air escapes there.",
                pic.leak_picture(shot, {n: (a[0], a[2]) for n, a in arrays.items()}, leaks)),
    ]


def _other_start(reg: Registration, mask: str) -> str:
    """A caption's sentences on how far the registration's other start put the contact band ("" with one start)."""
    apart = reg.other_run_apart_mm(load_template().regions[mask].band)
    if np.isnan(apart):
        return ""
    minor = "morphable" if reg.start == "affine" else "affine"
    lo, hi = reg.start_blend if reg.start_blend else (np.nan, np.nan)
    between = f"the affine start's over {hi:g}, and the two are blended between" if hi > lo else "the affine start's otherwise"
    weighed = (f" The morphable start's fit is kept when its bending times its distance from the scan is under {lo:g} of the "
               f"affine start's, {between}; here {reg.start_product:.3f}, "
               f"{100 * reg.morphable_share:.0f} % morphable. Near those bounds another scan of this face may weigh the fits "
               "otherwise, and the seal then lies up to that much further along the skin." if np.isfinite([reg.start_product, lo]).all() else "")
    return f" The template fitted from the {minor} start alone put the contact band {apart:.1f} mm (mean) from this one." + weighed


def design_pictures(al: Alignment, reg: Registration, contact: Contact, cushion: Face, face: Face, whole, close,
                    scene: Scene) -> list[Picture]:
    """The scan understood: landmarks, registration residual, contact curve and the cushion on the face
    (`scene`: the face's, `render.scene_of`)."""
    sim = al.similarity
    res = reg.residual[reg.valid]
    return [
        Picture("scan_landmarks.png", "The scan and its landmarks",
                "Landmarks found on the scan, coloured by how well each agrees with the others in the alignment "
                "(green: agrees; red: rejected as wrong). They should sit on the eyes, nose, lips and face outline.",
                pic.landmarks_picture(whole, al.landmarks)),
        Picture("registration_residual.png", "The template on the scan",
                "The template face warped onto the scan, coloured by its remaining distance to the scan; dark everywhere "
                "means the face shape was captured. Grey: no scan data there (holes, hair, edges).",
                pic.residual_picture(reg.vertices, load_template().faces, reg.residual, sim,
                                     f"residual median {np.median(res):.2f} mm, 95th percentile {np.percentile(res, 95):.2f} mm")),
        Picture("contact_curve.png", "Where the cushion touches the face",
                "The seal line carried from the template onto this face. Red stretches have no scan data under them; "
                "the cushion follows the template there." + _other_start(reg, contact.mask),
                pic.contact_picture((whole, close), contact.curve, contact.on_scan)),
        Picture("cushion_on_face.png", "The custom cushion on the face",
                "The printable cushion (blue) as designed on the scan.",
                pic.cushion_picture(face, cushion.vertices, cushion.faces, sim, scene)),
    ]


def mask_picture(face: Face, cushion: Face, frame: Face, sim: Similarity, scene: Scene) -> Picture:
    """The assembled mask, the `cushion` in its `frame` (mm, scan frame), on the face (`scene`: the face's, `render.scene_of`)."""
    return Picture("mask_on_face.png", "The assembled mask on the face",
                   "The cushion (blue) in its frame (white): the frame carries the 22 mm connector for the hose, the exhaust vents "
                   "on its upper side, the four headgear strap slots and, on an oronasal mask, the anti-asphyxia valve's opening "
                   "below the connector. The table above gives the mask's figures.",
                   pic.mask_picture(face, cushion, frame, sim, scene))


def report_files(d: Design, scan: Scan, fit: dict, mask_record: dict, provenance: Provenance, submit=at_once) -> dict[str, bytes]:
    """The pictures and report.html of a design (`fit` its fit.json record, `mask_record` its mask.json),
    as {name: bytes}. `submit(fn, *args)` (a process pool's, or `at_once`) draws the design's own
    pictures (`design_pictures`) while this process draws the assembled mask and the evaluation's."""
    sim, mask = d.alignment.similarity, d.contact.mask
    rims, window_kpa = evaluated_rims(d), d.fit_params.window_kpa
    face = scan_face(scan, d)
    shown = viewer_face(face, np.mean(d.contact.curve, axis=0))  # decimated, and its spent memory handed back, before the scene is built
    release()
    scene = scene_of(face.vertices, face.faces)
    whole = shoot(face, whole_face_view(sim), scene)
    close = shoot(Face(face.vertices, face.faces), seal_view(sim, np.vstack([d.contact.curve, *(r.points for r in rims.values())])), scene)
    cushion = Face(d.solid.vertices, d.solid.faces)
    frame = Face(d.frame.mesh.vertices, d.frame.mesh.faces)
    early = submit(design_pictures, d.alignment, d.registration, d.contact, cushion, face, whole, close, scene)
    scale = pressure_scale(rims, window_kpa)
    later = [mask_picture(face, cushion, frame, sim, scene),  # drawn here: the worker checks the solids' files first
             *gap_pictures(close, sim, mask, rims, fit), *pressure_pictures(close, sim, mask, rims, window_kpa, fit),
             state_picture(close, d, scale)]
    values = {n: np.asarray(r.pressure_kpa, dtype=float) for n, r in rims.items()}
    fig = viewer_figure(shown, cushion,
                        {n: (r.points, values[n]) for n, r in rims.items()}, scale, sim, d.cushion.axis)
    notices = (gate_notices(fit) + landmark_notices(d.alignment.landmarks)
               + scan_notices(d.contact.curve, d.contact.on_scan, sim, mask) + fit_notices(rims, window_kpa, sim, mask, at_seal_force(fit)))
    trace = (("cpapfit version", __version__), ("date", provenance.date), ("input", provenance.source),
             ("input SHA-256", provenance.sha256), ("scan units", scan.units_note or scan.units),
             ("mask", mask), ("landmarks", f"{len(d.alignment.landmarks.points)} by {d.alignment.landmarks.path}"),
             ("cushion parameters", ", ".join(f"{k} {v:g}" for k, v in vars(d.cushion.params).items())))
    pictures = early.result() + later
    page = Page(f"{mask.capitalize()} CPAP cushion for {provenance.source.rstrip('/').split('/')[-1]}", fit, tuple(notices),
                tuple(pictures), trace, viewer_html(fig), mask_record)
    return {**{p.name: p.png for p in pictures}, "report.html": report_html(page)}
