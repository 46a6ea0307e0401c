"""cpapfit from Python: the command line's work as functions over typed results.

    import cpapfit
    scan = cpapfit.load_scan(cpapfit.phantom(3, "subject"))  # a capture folder or a mesh file, in mm
    result = cpapfit.design(scan, mask="nasal")
    print(result.fit["custom"]["leak_l_min"], result.quality["rescan_advised"])
    result.save("out")  # the files of `cpapfit design`, written as one set

Everything is in millimetres in the scan's frame; `fit` and the saved files are those `cpapfit
design` writes (`docs/formats.md`, `cpapfit/schemas/`).
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

from .align.nonrigid import NonrigidParams
from .cushion.nurbs import CushionParams
from .errors import InputError
from .evaluation.fit import FitParams
from .evaluation.rim import require_dense
from .io import load_scan
from .io.landmarks import user_landmarks
from .outputs import design_files, report_files
from .pipeline import Design, evaluate as evaluated, evaluated_cushions, face_for, place_template, pressed_asleep
from .pipeline import design as designed
from .jobs import ScanTask, save_folder
from .landmarks.noise import LandmarkNoise
from .thresholds import QualityParams
from .records import evaluate_record, manifest_record
from .scan import Scan
from .stock_fit import compared_stock

__all__ = ["Params", "NonrigidParams", "CushionParams", "FitParams", "QualityParams", "LandmarkNoise", "DesignResult", "load_scan", "phantom", "design", "evaluate"]


@dataclass(frozen=True)
class Params:
    """Every setting of a design in one place: the template's registration, the cushion's shape, the
    fit model, the quality gates' thresholds, the stock cushion to compare with (a size,
    "gauge", "best" or None), and noise on the detected landmarks (robustness studies; none by default)."""

    registration: NonrigidParams = NonrigidParams()
    cushion: CushionParams = CushionParams()
    fit: FitParams = FitParams()
    quality: QualityParams = QualityParams()
    stock: str | None = "best"
    landmark_noise: LandmarkNoise = LandmarkNoise()


@dataclass(frozen=True)
class DesignResult:
    """A design and its files: `design` every stage's result, `files` {name: bytes} of everything
    `cpapfit design` writes (report included), `stock` the stock comparison it was made with."""

    design: Design
    scan: Scan
    files: dict = field(repr=False)
    stock: str | None = "best"

    @property
    def fit(self) -> dict:
        """fit.json: the fit, the checks and the quality gates' values (`docs/formats.md`)."""
        return json.loads(self.files["fit.json"])

    @property
    def quality(self) -> dict:
        """The quality gates: rescan_advised, warnings and every gate's value."""
        return self.design.quality.record()

    def save(self, folder: str | Path) -> Path:
        """Every file of the design and its manifest.json written into `folder` as one set
        (`jobs.save_folder`: new, empty or an earlier cpapfit design folder)."""
        folder = Path(folder)
        task = ScanTask(Path(self.scan.source), folder, self.design.contact.mask, self.scan.units, self.stock)
        save_folder(folder, self.files, manifest_record(task, tuple(self.files), None, {}))
        return folder


def phantom(seed: int, folder: str | Path, population: str = "ict", mouth_open_mm: float = 0.0) -> Path:
    """A synthetic subject (an RGB-D capture with its ground truth, `cpapfit phantom`) written into
    `folder`; the folder, for `load_scan`."""
    from .io.phantom import write_phantom
    from .synthetic.ict_phantom import make_ict_phantom
    from .synthetic.template_phantom import make_phantom

    make = make_ict_phantom if population == "ict" else make_phantom
    write_phantom(make(seed, mouth_open_mm=mouth_open_mm), Path(folder))
    return Path(folder)


def design(scan: Scan, mask: str = "nasal", landmarks: str | Path | None = None, params: Params = Params(),
           report: bool = True) -> DesignResult:
    """`cpapfit design` of a loaded scan: `landmarks` a landmarks file (in the scan's units) to use
    instead of detection; `report` whether to draw report.html and its pictures."""
    d = designed(scan, mask, user_landmarks(landmarks, scan), params.cushion, params.fit, stock=params.stock, quality=params.quality,
                 registration=params.registration, landmark_noise=params.landmark_noise)
    files = design_files(d, scan)
    return DesignResult(d, scan, files | (report_files(d, scan, files) if report else {}), params.stock)


def evaluate(scan: Scan, cushion, mask: str | None = None, generic: bool = False, stock: str | None = None,
             states: bool = False, force_n: float | None = None, landmarks: str | Path | None = None,
             params: Params = Params(), cushion_file: str = "") -> dict:
    """`cpapfit evaluate`: a cushion mesh (trimesh, mm, the scan's frame; from `cushion_file`) pressed
    onto the scan at `force_n` N (None: its recommended force, or with `states` the force set for
    them, `headgear_force`); with `mask`, the `generic` cushion at the same force, a `stock` cushion
    (a size, "gauge" or "best") fitted as a clinic fits it, and with `states` every state of the
    sleeping face. The fit.json record."""
    if (generic or stock or states) and not mask:
        raise InputError("generic, stock and states need the mask (nasal or oronasal): which cushion to compare with, which states to press")
    placed = place_template(scan, user_landmarks(landmarks, scan), params=params.registration, quality=params.quality,
                            landmark_noise=params.landmark_noise)
    require_dense(scan)
    face = face_for(scan, placed.alignment, placed.registration, cushion.vertices)
    cushions = evaluated_cushions(placed.alignment, cushion, mask if generic else None, params.cushion)
    if states:
        fits, pressed = pressed_asleep(face, cushions, mask, params.cushion, params.fit, force_n)
    else:
        fits, pressed = evaluated(face, cushions, params.cushion, params.fit, force_n), None
    compared = compared_stock(mask, face, stock, params.cushion, params.fit, asleep=states) if stock else None
    fits |= compared.fits if compared else {}
    pressed = compared.beside(pressed) if compared and pressed else pressed
    return evaluate_record(scan, cushion_file, fits, params.fit, compared, pressed)

