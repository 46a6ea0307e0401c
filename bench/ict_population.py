"""Designs on faces the template was not made from: ICT Face Model subjects (`cpapfit.ict`), end to
end (`pipeline.design`), both masks, as an RGB-D capture an operator framed (`make_ict_phantom`,
`camera.FRAMED`) and as a head mesh scan with its modelled nostril and lip insides
(`ict_head_mesh`), turned and moved at random (a mesh may come in any orientation). The faces are
drawn from the full ICT model (`load_ict(path)`: all 100 identity modes, `--model`, by default
../shared/data/ict_face_model/ict_face_model.npz when present, else the shipped 40 modes), so
they lie outside the span of the shipped 40 modes a registration may use as its shape prior.

One placement of the template (`place_template`) serves both masks of a scan. Per design: made or
refused (and why), flagged ("rescan advised", with the gates), how the template
was placed (landmarks by image, render, or the shape alone), and against the truth (the template
mapped onto the ICT face, `template_truth`):
- band: the registered template's contact band of that mask, mean and 95th percentile of the
  distances of its vertices from their true positions (mm);
- curve: the seal curve carried by the registration (the same barycentric points), mean (mm);
- landmarks: the registered template's Face Mesh landmarks against the model's own Multi-PIE
  landmarks of the same definition, 9 points without the nose tip (mm); the same measure of the
  truth itself (the correspondence's own definitional offset) is printed beside it;
- depth_ratio, face_size: the face's proportions against the template's (`proportions.py`), and
  true_depth_ratio: the truth's over the same template vertices (those the registration matched).
Silently wrong: made, not flagged, band mean over 2 mm; misplaced: band mean over 5 mm (made at all).
Awake, the custom cushion at its force on the scan: leak, peak pressure and window (`fit.json`'s), and
how deep the fit model presses each rim point (its travel along the axis times |cos|) against that
point's depth in the true face at the equilibrium (its distance to the nearest point of the truth's
triangles, `trimesh.proximity`): the 95th percentile and largest difference over the rim points in
contact.

Usage: .venv/bin/python bench/ict_population.py [--seeds 50] [--first 2000] [--workers 2] [--kinds capture mesh] [--masks nasal oronasal]
       [--model NPZ | --model shipped]
"""

import argparse
import json
import platform
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from cpapfit import __version__
from cpapfit.cushion.contact import template_curve
from cpapfit.errors import CpapfitError
from cpapfit.ict import MULTIPIE_TO_FACEMESH, load_ict, random_subject
from cpapfit.synthetic.ict_phantom import ict_head_mesh, make_ict_phantom
from cpapfit.io import load_scan
from cpapfit.io.capture import capture_files
from cpapfit.io.write import write_files
from cpapfit.synthetic.camera import FRAMED, to_camera
from cpapfit.evaluation.fit import FitParams
from cpapfit.evaluation.mechanics import COS_MIN
from cpapfit.pipeline import design, place_template
from cpapfit.quality.proportions import proportions
from cpapfit.template import MASKS, load_template
from ict_bench import model_argument, model_source

POINTS = (31, 33, 35, 36, 39, 42, 45, 48, 54)  # Multi-PIE: nose base, eye corners, mouth corners (no nose tip)
INDEX = [MULTIPIE_TO_FACEMESH[p] for p in POINTS]  # their template vertices
CAPILLARY_KPA = FitParams().capillary_kpa  # the awake peak's limit


def subject(seed: int, kind: str, source: Path | None = None):
    """(scan, truth (N, 3) template order, ICT landmarks (9, 3)), all mm in the scan's frame; the
    face drawn from the ICT model file `source` (`load_ict(source)`: the shipped model if None)."""
    model = load_ict(source)
    face = random_subject(np.random.default_rng(seed), 0.0, model)[0]
    marks = face[model.landmarks[list(POINTS)]]
    with tempfile.TemporaryDirectory() as tmp:
        if kind == "capture":
            ph = make_ict_phantom(seed, pose=FRAMED, model=model)
            write_files(Path(tmp), capture_files(ph.image, ph.depth_raw, ph.intrinsics, ph.sensor.depth_scale))
            return load_scan(Path(tmp)), ph.surface, to_camera(marks, ph.pose)
        head = ict_head_mesh(seed, model=model)
        rng = np.random.default_rng(seed + 7919)
        turn = Rotation.random(random_state=rng).as_matrix()
        shift = rng.uniform(-300.0, 300.0, 3)
        mesh = head.mesh.copy()
        mesh.apply_transform(np.block([[turn, shift[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]]))
        path = Path(tmp) / "head.ply"
        path.write_bytes(mesh.export(file_type="ply"))
        return load_scan(path), head.truth @ turn.T + shift, marks @ turn.T + shift


def run(job: tuple[int, str, tuple[str, ...], Path | None]) -> list[dict]:
    """The designs of subject `seed` (drawn from the model file `source`, None: the shipped model) as
    a `kind` scan with each of `masks`, from one placement of the template, measured against its truth."""
    seed, kind, masks, source = job
    scan, truth, marks = subject(seed, kind, source)
    rows = [{"seed": seed, "kind": kind, "mask": mask, "truth_landmarks_mm": float(np.linalg.norm(truth[INDEX] - marks, axis=1).mean())}
            for mask in masks]
    try:
        placed = place_template(scan)
    except CpapfitError as exc:
        return [{**row, "outcome": "refused", "reason": str(exc)[:200]} for row in rows]
    return [_measured(row, scan, placed, truth, marks) for row in rows]


def _measured(row: dict, scan, placed, truth: np.ndarray, marks: np.ndarray) -> dict:
    """`row` with the design of its mask from `placed` against the truth, or why it was refused."""
    mask, template = row["mask"], load_template()
    try:
        d = design(scan, mask, placement=placed)
    except CpapfitError as exc:
        return {**row, "outcome": "refused", "reason": str(exc)[:200]}
    v, fit = d.registration.vertices, d.fits["custom"].summary()
    band = np.linalg.norm(v[template.regions[mask].band] - truth[template.regions[mask].band], axis=1)
    tri, bary = template_curve(mask)
    curve = [np.einsum("kj,kjc->kc", bary, x[template.faces[tri]]) for x in (v, truth)]
    return {
        **row, "outcome": "made", "flags": [g.code for g in d.quality.flags], "path": d.alignment.landmarks.path,
        "start": d.registration.start,
        "band_mm": float(band.mean()), "band_p95_mm": float(np.percentile(band, 95)),
        "curve_mm": float(np.linalg.norm(curve[0] - curve[1], axis=1).mean()),
        "landmarks_mm": float(np.linalg.norm(v[INDEX] - marks, axis=1).mean()),
        **{g.code: g.value for g in d.quality.gates if g.code in ("depth_ratio", "face_size")},
        "true_depth_ratio": proportions(template.vertices, d.alignment.similarity, replace(d.registration, vertices=truth)).depth_ratio,
        "leak_l_min": fit["leak_l_min"], "peak_kpa": fit["pressure_max_kpa"], "window": fit["window_fraction"],
        **depth_error(d.fits["custom"], true_face(truth, template.faces)),
    }


def true_face(truth: np.ndarray, faces: np.ndarray) -> trimesh.Trimesh:
    """The true face (N, 3) mm in the template's (F, 3) triangles, less those of no height (the
    template's closest-point map onto the ICT face leaves slivers in the crease under the wing of
    the nose, whose barycentric coordinates are NaN)."""
    mesh = trimesh.Trimesh(truth, faces, process=False)
    mesh.update_faces(mesh.nondegenerate_faces(height=1e-4))
    return mesh


def depth_error(fit, truth: trimesh.Trimesh) -> dict:
    """The fit model's depth of each rim point in contact (mm: travel along the axis times |cos|)
    against its depth in the `truth` (the true face, whole, in the template's triangles) at the
    equilibrium (which side of the skin: the vertex normals at the nearest point): p95 and largest
    |difference| (NaN with no contact). This measures the whole reading on a scan: which skin, how
    deep under it, and the model's linear law."""
    rim, c = fit.rim, fit.rim.covered
    cos = np.maximum(rim.cos[c], COS_MIN)
    travel = fit.pressed.pressure_kpa / (fit.stiffness.effective[c] * cos)
    at = rim.points[c] - (travel + rim.clearance[c])[:, None] * rim.axis  # each rim point where the mask came to rest
    nearest, distance, tri = trimesh.proximity.closest_point(truth, at)
    corners = np.asarray(truth.faces)[tri]
    weights = trimesh.triangles.points_to_barycentric(np.asarray(truth.vertices)[corners], nearest)
    out = np.einsum("kj,kjc->kc", weights, np.asarray(truth.vertex_normals)[corners])
    out *= np.sign(np.nanmedian(out @ rim.axis))  # out of the face
    exact = distance * np.where(np.einsum("ij,ij->i", at - nearest, out) < 0, 1.0, -1.0)
    error = np.abs(travel * cos - exact)[(travel > 0) & np.isfinite(out).all(axis=1)]
    if not len(error):
        return {"depth_err_p95_mm": float("nan"), "depth_err_max_mm": float("nan")}
    return {"depth_err_p95_mm": float(np.percentile(error, 95)), "depth_err_max_mm": float(error.max())}


def table(rows: list[dict]) -> str:
    """Markdown: one line per (kind, mask) and one for all."""
    out = ["| scans | mask | n | designed | flagged | refused | band mean (mm) | band p95 (mm) | curve (mm) | landmarks (mm) "
           "| truth's landmarks (mm) | over 5 mm | silently wrong (> 2 mm) |", "|---" * 13 + "|"]
    for (kind, mask), rs in (_groups(rows) | {("all", "both"): rows}).items():
        made = [r for r in rs if r["outcome"] == "made"]
        mean = lambda key: f"{np.mean([r[key] for r in made]):.2f}" if made else "-"  # noqa: E731
        out.append(
            f"| {kind} | {mask} | {len(rs)} | {100 * len(made) / len(rs):.0f} % | {sum(bool(r['flags']) for r in made)} "
            f"| {len(rs) - len(made)} | {mean('band_mm')} | {mean('band_p95_mm')} | {mean('curve_mm')} | {mean('landmarks_mm')} "
            f"| {np.mean([r['truth_landmarks_mm'] for r in rs]):.2f} | {sum(r['band_mm'] > 5.0 for r in made)} "
            f"| {sum(r['band_mm'] > 2.0 and not r['flags'] for r in made)} |")
    return "\n".join(out)


def _groups(rows: list[dict]) -> dict:
    """{(kind, mask): its rows}, in the order first met."""
    groups = {}
    for r in rows:
        groups.setdefault((r["kind"], r["mask"]), []).append(r)
    return groups


def awake(rows: list[dict]) -> str:
    """Markdown: the custom cushions awake, per (kind, mask)."""
    out = ["| scans | mask | n | peak median (kPa) | peak over 4.3 kPa | largest peak (kPa) | window under 95 % | leak over 1 L/min "
           "| depth error p95, median of designs (mm) | largest depth error (mm) |", "|---" * 10 + "|"]
    for (kind, mask), rs in _groups([r for r in rows if r["outcome"] == "made"]).items():
        col = lambda key: np.array([r[key] for r in rs])  # noqa: E731
        out.append(f"| {kind} | {mask} | {len(rs)} | {np.median(col('peak_kpa')):.2f} | {np.sum(col('peak_kpa') > CAPILLARY_KPA)} "
                   f"| {col('peak_kpa').max():.2f} | {np.sum(col('window') < 0.95)} | {np.sum(col('leak_l_min') > 1.0)} "
                   f"| {np.median(col('depth_err_p95_mm')):.2f} | {col('depth_err_max_mm').max():.2f} |")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--first", type=int, default=2000)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--kinds", nargs="+", default=["capture", "mesh"], choices=["capture", "mesh"])
    ap.add_argument("--masks", nargs="+", default=list(MASKS), choices=list(MASKS))
    ap.add_argument("--rows", type=Path, default=None, help="also write every design's row here (JSON lines)")
    model_argument(ap)
    args = ap.parse_args()
    source = model_source(args)
    model = load_ict(source)
    drawn = f"{len(model.identity)} identity modes of {source}" if source else f"the shipped {len(model.identity)} identity modes"
    print(f"cpapfit {__version__}, {platform.machine()}, Python {platform.python_version()}; ICT seeds "
          f"{args.first}-{args.first + args.seeds - 1} ({drawn}); {' and '.join(args.kinds)}; {' and '.join(args.masks)}; {args.workers} workers")
    jobs = [(seed, kind, tuple(args.masks), source) for seed in range(args.first, args.first + args.seeds) for kind in args.kinds]
    rows, t0 = [], time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        for row in (r for done in pool.map(run, jobs) for r in done):
            rows.append(row)
            print(" ", json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in row.items()}), flush=True)
    if args.rows:
        args.rows.write_text("".join(json.dumps(r) + "\n" for r in rows))
    print()
    print(table(rows))
    made = [r for r in rows if r["outcome"] == "made" and "depth_ratio" in r]
    if made:
        off = np.array([r["depth_ratio"] - r["true_depth_ratio"] for r in made])
        print(f"\ndepth ratio read against the truth's over the same vertices: mean {off.mean():+.3f}, largest |difference| "
              f"{np.abs(off).max():.3f}; read {min(r['depth_ratio'] for r in made):.3f}-{max(r['depth_ratio'] for r in made):.3f}")
    print()
    print(awake(rows))
    print(f"\ntotal time {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
