"""The finite-element reference and what it says of the fast fit model's springs.

1. Cases with known answers (`cpapfit.evaluation.fe_checks`, fine meshes): plates under pressure, the
   Hertz cylinder, a confined layer.
2. The skin: each tissue region of the fit model (`tissue.REGIONS`: E, depth over bone) pressed by a
   rigid strip as wide as the seal flange (5 mm), plane strain, Poisson 0.49 (`strip_stiffness`),
   beside the Winkler figure E / h and the spring the fast model ships (the same computation).
3. The cushion: slices of designed walls (`section_stiffness`), ICT subjects' head meshes from the
   full model, both masks, SECTIONS slices around each rim; frictionless and bonded to the skin
   (the two bounds of a flange that grips), beside the fast model's flange spring
   (`TissueModel.cushion_kpa_per_mm`), and what the two in series give.
4. With --membrane, instead: the membrane (`cpapfit.evaluation.fe_membrane`, geometrically nonlinear):
   for flaps of the cushions' thickness (or --thickness) and widths at CPAP 4, 10 and 20 cmH2O, the largest seal
   opening at which the flap still lies BAND_MM on the skin (`sealed_opening`), as designed (its
   root's stand-off and rest lift) and flat, on a rigid skin and on the softest region's, beside the
   fast model's `reach_mm`, the same law for a flat flap, and a free cantilever's tip deflection,
   min(w - BAND_MM, P w^4 / (8 D)); and how hard the designed flap's root pulls its wall towards the
   skin at no opening (`root_pull`) beside the fast model's `root_pull_kpa_mm`; nan where Newton's
   iterations fail.

Usage: .venv/bin/python bench/fe_calibration.py [--seeds 6] [--first 8000] [--model NPZ | --model shipped]
       [--membrane [--widths MM ...] [--thickness MM]]
"""

import argparse
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from cpapfit import __version__
from cpapfit.cushion.nurbs import CushionParams
from cpapfit.errors import CpapfitError
from cpapfit.cushion.envelope import THINNEST_MM
from cpapfit.cushion.nurbs import MEMBRANE_LIFT, MEMBRANE_ROOT_MM
from cpapfit.evaluation.calibration import root_pull, sealed_opening, section_stiffness, strip_stiffness
from cpapfit.evaluation.fe_membrane import Flap, NotConverged
from cpapfit.evaluation.fit import KPA_PER_CMH2O
from cpapfit.evaluation.membrane import BAND_MM, bending_stiffness, reach_mm, root_pull_kpa_mm
from cpapfit.evaluation.fe_checks import all_checks
from cpapfit.evaluation.tissue import REGIONS, TissueModel
from cpapfit.ict import load_ict
from cpapfit.synthetic.ict_phantom import ict_head_mesh
from cpapfit.io import load_scan
from cpapfit.pipeline import design, place_template
from cpapfit.template import MASKS
from ict_bench import model_argument, model_source

SECTIONS = 16
WALL_MM, FLANGE_MM, FLAP_MM = CushionParams().wall_mm, CushionParams().flange_mm, CushionParams().membrane_mm
FLAP_WIDTHS_MM = (3.0, 4.0, 5.0, 6.0, 8.0, 10.0)  # narrow flaps to about the envelope's width
CPAP_CMH2O = (4.0, 10.0, 20.0)
FLAP_CELLS = (48, 2)


def profiles(seed: int, source: Path | None) -> dict[str, list[np.ndarray]]:
    """{mask: SECTIONS (P, 2) mm wall profiles (across the rim, along the axis), seal to frame}."""
    mesh = ict_head_mesh(seed, model=load_ict(source)).mesh
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "head.ply"
        path.write_bytes(mesh.export(file_type="ply"))
        scan = load_scan(path)
    placed = place_template(scan)
    out = {}
    for mask in MASKS:
        try:
            cushion = design(scan, mask, placement=placed).cushion
        except CpapfitError:
            continue
        grid, axis = cushion.grid(SECTIONS, 40), cushion.axis
        centre = grid[:, 0].mean(axis=0)
        out[mask] = []
        for wall in grid:
            outward = wall[0] - centre - ((wall[0] - centre) @ axis) * axis
            outward /= np.linalg.norm(outward)
            out[mask].append(np.column_stack([(wall - wall[0]) @ outward, (wall - wall[0]) @ axis]))
    return out


def sealed_or_none(flap: Flap, cpap_kpa: float, spring: float | None = None) -> tuple[float, float]:
    """`sealed_opening` on a rigid skin (None) or a soft one, (nan, nan) where Newton fails."""
    try:
        return sealed_opening(flap, cpap_kpa, BAND_MM) if spring is None else sealed_opening(flap, cpap_kpa, BAND_MM, spring)
    except NotConverged:
        return np.nan, np.nan


def pull_or_nan(flap: Flap, cpap_kpa: float) -> float:
    """`root_pull` (kPa mm) of a flap that lies BAND_MM on a rigid skin at no opening; nan where it lies less or Newton fails."""
    try:
        pull, lying = root_pull(flap, cpap_kpa)
    except NotConverged:
        return np.nan
    return pull if lying >= BAND_MM else np.nan


def membrane_table(widths: tuple[float, ...], thickness: float = FLAP_MM) -> None:
    """The membrane's sealed opening by finite elements beside the fast model's reach (module docstring),
    for flaps `widths` mm wide and `thickness` mm thick."""
    soft = min(REGIONS.values(), key=lambda r: r[2])
    rigidity = bending_stiffness(thickness)
    print(f"membrane {thickness:g} mm silicone (E 1 MPa, nu 0.49), mesh {FLAP_CELLS[0]} x {FLAP_CELLS[1]} quadratic triangles, "
          f"band {BAND_MM:g} mm; designed: root {MEMBRANE_ROOT_MM[1]:g} mm off the skin, rest lift {MEMBRANE_LIFT:g}; "
          f"soft skin {soft[2]:.2f} kPa/mm (the softest region's spring)\n")
    print("| width (mm) | CPAP (cmH2O) | free cantilever | reach_mm | FE designed, rigid | law, flat flap | FE flat, rigid "
          "| FE flat, soft | lies at no opening, designed (mm) | root's pull, FE / law (kPa mm per mm) |\n|---|---|---|---|---|---|---|---|---|---|")
    for width in widths:
        for cmh2o in CPAP_CMH2O:
            p = cmh2o * KPA_PER_CMH2O
            flat = Flap(width, thickness, cells=FLAP_CELLS)
            designed = Flap(width, thickness, MEMBRANE_ROOT_MM[1], MEMBRANE_LIFT, FLAP_CELLS)
            cantilever = min(width - BAND_MM, p * width**4 / (8.0 * rigidity))
            laid_flat = min(p * (width - BAND_MM + thickness) ** 4 / (72.0 * rigidity), width - BAND_MM)
            rigid, soft_g = sealed_or_none(flat, p)[0], sealed_or_none(flat, p, soft[2])[0]
            lifted, lies = sealed_or_none(designed, p)
            law = float(reach_mm(np.array([width]), np.array([thickness]), p)[0])
            pull = float(root_pull_kpa_mm(np.array([width]), np.array([thickness]), p)[0])
            print(f"| {width:g} | {cmh2o:g} | {cantilever:.2f} | {law:.2f} | {lifted:.2f} | {laid_flat:.2f} | {rigid:.2f} | {soft_g:.2f} "
                  f"| {lies:.2f} | {pull_or_nan(designed, p):.2f} / {pull:.2f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--first", type=int, default=8000)
    model_argument(ap)
    ap.add_argument("--membrane", action="store_true", help="the membrane's sealed opening instead")
    ap.add_argument("--widths", type=float, nargs="+", default=FLAP_WIDTHS_MM, help="the membrane's widths, mm")
    ap.add_argument("--thickness", type=float, default=FLAP_MM, help=f"the membrane's thickness, mm (the design's thinnest: {THINNEST_MM:g})")
    args = ap.parse_args()
    source = model_source(args)
    print(f"cpapfit {__version__}, {platform.machine()}, Python {platform.python_version()}")
    t0 = time.perf_counter()
    if args.membrane:
        membrane_table(tuple(args.widths), args.thickness)
        print(f"\ntotal time {time.perf_counter() - t0:.0f} s")
        return
    print("\n| case | computed | closed form | error |\n|---|---|---|---|")
    for c in all_checks(fine=True):
        print(f"| {c.name} | {c.computed:.4f} {c.unit} | {c.expected:.4f} {c.unit} | {100 * c.error:+.2f} % |")
    print(f"\nskin under a {FLANGE_MM:g} mm strip (Poisson 0.49):\n\n| region | E (kPa) | depth (mm) | Winkler E/h (kPa/mm) "
          "| finite elements (kPa/mm) | ratio | fit model's spring (kPa/mm) |\n|---|---|---|---|---|---|---|")
    for name, (e, h, shipped, _) in REGIONS.items():
        k = strip_stiffness(e, h, FLANGE_MM, cells=48)
        print(f"| {name} | {e:g} | {h:g} | {e / h:.2f} | {k:.2f} | {k / (e / h):.2f} | {shipped:.2f} |")
    spring = TissueModel().cushion_kpa_per_mm
    print(f"\ncushion walls, ICT seeds {args.first}-{args.first + args.seeds - 1}, {SECTIONS} slices a rim, {WALL_MM:g} mm silicone "
          f"(E 1 MPa, Poisson 0.49), the fast model's flange spring {spring:g} kPa/mm:\n")
    print("| mask | slices | frictionless: p10 / median / p90 (kPa/mm) | bonded: p10 / median / p90 (kPa/mm) |\n|---|---|---|---|")
    walls = {mask: [] for mask in MASKS}
    for seed in range(args.first, args.first + args.seeds):
        for mask, profs in profiles(seed, source).items():
            walls[mask] += [(section_stiffness(p, WALL_MM, FLANGE_MM), section_stiffness(p, WALL_MM, FLANGE_MM, bonded=True)) for p in profs]
    for mask, ks in walls.items():
        k = np.array(ks)
        cells = [" / ".join(f"{v:.2f}" for v in np.percentile(k[:, i], [10, 50, 90])) for i in range(2)]
        print(f"| {mask} | {len(k)} | {cells[0]} | {cells[1]} |")
    print(f"\ntotal time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
