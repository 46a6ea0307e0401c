"""cpapfit's non-rigid registration against trimesh's `trimesh.registration.nricp_amberg`, side by
side in one run on the same inputs, on real-sized scans of faces the template was not made from.

Cases: ICT heads (`ict_head_mesh(seed)` of the full ICT model, ../shared/data/ict_face_model: the
whole modelled head with its nostril and lip insides, mm, read back as a PLY scan file is), whose
true template vertices are known (`HeadMesh.truth`, `template_truth`); and fran
(../shared/data/fran_cyberware, a Cyberware scan in metres), fit only. Each is skipped, with a
line saying so, where ../shared lacks it.

cpapfit: `place_template`, what `cpapfit register` does once the scan is read: landmarks and
similarity (`align`), then the registration stage (`registered`: the registration, and one more from
the face's shape alone where detected landmarks are doubtful), timed from the stage callback; each
registration run in it is printed too. The one-off loads a process pays at its first scan
(MediaPipe Face Mesh, the ICT shape basis of the morphable start) are made before the cases and
printed apart, so that no case carries them.
nricp_amberg: the template as cpapfit's registration starts from it (the similarity the placement
kept applied to the template's vertices, with its faces), the same scan mesh, the same landmarks
(the template indices and scan points cpapfit trusts: `_landmark_targets`), its default steps with
the stiffness scaled to mm (STEPS), distance_threshold 5 mm.
Fits, both: the scan-to-template distance over the mask region (`mask_region`: both masks' contact
bands; scan points whose nearest template triangle lies in it), median and p95 (mm), and where the
truth is known the correspondence: the mean distance (mm) of the registered mask-region vertices
from their true positions; the truth's own scan-to-template distance is printed beside them (the ICT
head's modelled nostril insides lie off the template's skin, which sets its p95). Times: wall and
CPU of the whole process (cpapfit runs its two starts in two threads), and their ratios; cpapfit's
are its median run's of `--repeat` (each run's printed: the machine's speed drifts by 10-25 % from
minute to minute), nricp_amberg's of its one run (80-100 s on an ICT head).

Usage: .venv/bin/python bench/speed.py [--cases ict fran] [--seeds 8003 8020] [--repeat 3]
"""

import argparse
import os
import platform
import subprocess
import time
from pathlib import Path

from cpapfit import __version__  # first: it sets OpenBLAS to one thread, as `cpapfit register` runs, before numpy loads it

import numpy as np
import trimesh

import cpapfit.pipeline as pipeline
from cpapfit.align.nonrigid import NonrigidParams, _landmark_targets
from cpapfit.ict import load_ict
from cpapfit.io import load_scan
from cpapfit.landmarks.facemesh import detect
from cpapfit.synthetic.ict_phantom import ict_head_mesh
from ict_bench import FULL_MODEL, scan_of
from nonrigid import REGION, TEMPLATE, correspondence, scan_to_template

SHARED = FULL_MODEL.parents[1]
FRAN = SHARED / "fran_cyberware" / "fran.obj"
STEPS = [[0.02, 10, 0.5, 10], [0.007, 5, 0.5, 10], [0.002, 2.5, 0.5, 10], [0.0005, 0, 0.0, 10]]  # nricp_amberg's defaults, stiffness scaled to mm
DISTANCE_MM = 5.0


def stolen() -> float:
    """Seconds of CPU the host has taken from this machine's cores so far (/proc/stat's steal; 0 where unknown)."""
    stat = Path("/proc/stat")
    fields = stat.read_text().split("\n", 1)[0].split() if stat.exists() else []
    return int(fields[8]) / os.sysconf("SC_CLK_TCK") if len(fields) > 8 else 0.0


class Clock:
    """Wall and CPU (whole process) seconds since it was made; `steal()`: CPU seconds the host took meanwhile."""

    def __init__(self):
        self.wall, self.cpu, self.stolen = time.perf_counter(), time.process_time(), stolen()

    def read(self) -> tuple[float, float]:
        return time.perf_counter() - self.wall, time.process_time() - self.cpu

    def steal(self) -> float:
        return stolen() - self.stolen


def header() -> None:
    here = Path(__file__).resolve().parents[1]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=here).stdout.strip()
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True, cwd=here).stdout.strip()
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), "?") if Path("/proc/cpuinfo").exists() else "?"
    print(f"machine: {platform.machine()}, {cpu}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}; Python {platform.python_version()}; "
          f"cpapfit {__version__} at {commit}{' with uncommitted changes' if dirty else ''}; trimesh {trimesh.__version__}")
    print(f"template: {len(TEMPLATE.vertices)} vertices, {len(TEMPLATE.faces)} triangles; mask region (both masks' contact bands) "
          f"{len(REGION)} vertices; nricp_amberg steps {STEPS}, distance_threshold {DISTANCE_MM:g} mm")
    clock = Clock()
    detect(np.zeros((64, 64, 3), dtype=np.uint8))
    face_mesh = clock.read()
    clock = Clock()
    pipeline.template_basis(NonrigidParams().morphable.modes)
    basis = clock.read()
    print(f"one-off loads before the cases (`cpapfit register` pays them once per process), wall s (CPU s): "
          f"MediaPipe Face Mesh {face_mesh[0]:.2f} ({face_mesh[1]:.2f}), ICT shape basis {basis[0]:.2f} ({basis[1]:.2f})")


def cases(which: list[str], seeds: list[int]):
    """(name, scan, truth (N, 3) mm in the scan's frame or None) of each case asked for that ../shared holds."""
    if "ict" in which:
        if FULL_MODEL.is_file():
            model = load_ict(FULL_MODEL)
            for seed in seeds:
                head = ict_head_mesh(seed, model=model)
                yield f"ICT head {seed}", scan_of(head.mesh), head.truth
        else:
            print(f"ICT heads skipped: no {FULL_MODEL}")
    if "fran" in which:
        if FRAN.is_file():
            yield "fran", load_scan(FRAN), None
        else:
            print(f"fran skipped: no {FRAN}")


def placed(scan):
    """cpapfit's `place_template` on `scan`: (placement, whole (wall, CPU) s, registration stage (wall, CPU) s,
    [wall s of each registration run in it])."""
    marks, runs = {}, []
    register_template = pipeline.register_template

    def counted(*args, **kwargs):
        clock = Clock()
        reg = register_template(*args, **kwargs)
        runs.append(clock.read()[0])
        return reg

    pipeline.register_template = counted  # `registered` and its second placement call it through the module
    try:
        clock = Clock()
        placement = pipeline.place_template(scan, on_stage=lambda stage: marks.__setitem__(stage, clock.read()))
        whole = clock.read()
    finally:
        pipeline.register_template = register_template
    start = marks["non-rigid registration"]
    return placement, whole, (whole[0] - start[0], whole[1] - start[1]), runs


def amberg(aligned: np.ndarray, scan, index: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, tuple[float, float]]:
    """nricp_amberg's registered vertices and its (wall, CPU) s."""
    clock = Clock()
    vertices = trimesh.registration.nricp_amberg(
        trimesh.Trimesh(aligned, TEMPLATE.faces, process=False), trimesh.Trimesh(scan.vertices, scan.faces, process=False),
        source_landmarks=index if len(index) else None, target_positions=points if len(index) else None,
        steps=STEPS, distance_threshold=DISTANCE_MM,
    )
    return np.asarray(vertices), clock.read()


def placed_repeatedly(scan, repeat: int) -> tuple[tuple, list[float]]:
    """`placed` run `repeat` times: the run whose registration stage took the median wall time, and
    each run's stage wall s; AssertionError if two runs register the scan to other vertices."""
    tries = [placed(scan) for _ in range(repeat)]
    if not all(np.array_equal(t[0].registration.vertices, tries[0][0].registration.vertices) for t in tries):
        raise AssertionError("the same scan registered twice to other vertices")
    walls = [t[2][0] for t in tries]
    return tries[int(np.argsort(walls)[len(walls) // 2])], walls


def compare(name: str, scan, truth: np.ndarray | None, repeat: int) -> None:
    print(f"\n{name}: scan {len(scan.vertices)} vertices, {len(scan.faces)} triangles ({scan.units_note}); load {os.getloadavg()[0]:.2f}")
    clock = Clock()
    (placement, whole, stage, runs), walls = placed_repeatedly(scan, repeat)
    al, reg = placement.alignment, placement.registration
    aligned = al.similarity.apply(TEMPLATE.vertices)  # as `register_template` starts from it
    index, points = _landmark_targets(al.landmarks, NonrigidParams())
    print(f"  cpapfit place_template, {repeat} run(s), the registration stage's wall s: {', '.join(f'{w:.2f}' for w in walls)}; the median run:")
    print(f"  cpapfit place_template: {whole[0]:.2f} s wall ({whole[1]:.2f} s CPU), of which the registration stage "
          f"{stage[0]:.2f} s ({stage[1]:.2f} s CPU): {len(runs)} register_template call(s) of {', '.join(f'{t:.2f}' for t in runs)} s "
          f"(each: the elastic ICP from the affine and from the morphable start, in two threads); kept: start {reg.start}, {len(reg.log)} iterations")
    print(f"  both start from the similarity-aligned template, {len(aligned)} vertices, with {len(index)} landmarks "
          f"(by {al.landmarks.path}{'; ' + al.landmarks.rejected if al.landmarks.rejected else ''})"
          + (f"; correspondence at that start {correspondence(aligned, truth):.3f} mm" if truth is not None else ""))
    theirs, t_theirs = amberg(aligned, scan, index, points)
    print(f"  {'':12}  {'wall s':>8}  {'CPU s':>8}  scan-to-template median / p95 (mm)  correspondence (mm)")
    rows = [("cpapfit", reg.vertices, f"{stage[0]:8.2f}  {stage[1]:8.2f}"), ("nricp_amberg", theirs, f"{t_theirs[0]:8.2f}  {t_theirs[1]:8.2f}")]
    if truth is not None:  # the fit's floor on this scan: its points off the template's skin (the modelled nostril insides)
        rows.append(("the truth", truth, f"{'':8}  {'':8}"))
    for method, vertices, times in rows:
        d = scan_to_template(scan, vertices)
        corr = f"{correspondence(vertices, truth):.3f}" if truth is not None else "no truth"
        print(f"  {method:12}  {times}  {np.median(d):.3f} / {np.percentile(d, 95):.3f} ({len(d)} scan points){'':4}{corr}")
    print(f"  time ratio nricp_amberg / cpapfit registration stage: {t_theirs[0] / stage[0]:.1f}x wall, {t_theirs[1] / stage[1]:.1f}x CPU "
          f"(/ whole place_template: {t_theirs[0] / whole[0]:.1f}x); during the case: load {os.getloadavg()[0]:.2f}, "
          f"{clock.steal():.1f} CPU s taken by the host from this machine's {os.cpu_count()} cores")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", nargs="+", choices=["ict", "fran"], default=["ict", "fran"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[8003, 8020], help="the ICT heads' seeds")
    ap.add_argument("--repeat", type=int, default=3, help="cpapfit's runs a case, the median's times kept (nricp_amberg runs once)")
    args = ap.parse_args()
    header()
    for name, scan, truth in cases(args.cases, args.seeds):
        compare(name, scan, truth, args.repeat)


if __name__ == "__main__":
    main()
