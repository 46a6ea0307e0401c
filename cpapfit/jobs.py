"""Units of work at the edge, from files to files: one `design` run, and the idempotent batch job
around it (content hash, hidden staging folder renamed into place, manifest written last).

A batch job's outputs go to OUT_DIR/<name>/, which holds either the complete outputs of the scan
as it is now, with `manifest.json`, or nothing: they are built in a hidden `.<name>.tmp-*` folder
beside it and renamed into place; a run killed midway leaves only hidden folders, which
`clean_leftovers` removes.
"""

import contextlib
import hashlib
import json
import multiprocessing
import os
import re
import shutil
import time
import uuid
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from functools import partial
from importlib import import_module
from pathlib import Path
from typing import Callable

from . import __version__
from .cushion.population import population
from .errors import CpapfitError, InputError
from .io import is_fused, load_scan
from .outputs import in_order, record_files, report_files, solid_files
from .io.landmarks import user_landmarks
from .io.mesh import companion_files
from .io.sweep import fused_ply
from .io.write import json_bytes, write_bytes, write_files
from .memory import release, settled
from .pipeline import Design, design
from .records import manifest_record
from .work import at_once, released

MANIFEST = "manifest.json"
LEFTOVER = re.compile(r"^\..+\.(tmp|old)-\w+$")  # hidden staging names in OUT_DIR


def _silent(stage: str) -> None:
    """The default stage callback: nothing."""


@dataclass(frozen=True)
class DesignRun:
    """What one design run wrote: `fit` (the contents of fit.json), how the scan's unit was decided,
    the names of the files written, and the design itself."""

    fit: dict
    units_note: str
    files: tuple[str, ...]
    design: Design


@contextlib.contextmanager
def worker(parallel: bool, shared: Callable[[], object] | None = None):
    """`submit` for work done alongside (`work.py`): a worker process forked now, while this process
    runs a single thread (a fork copies only the calling thread: one taken after MediaPipe or Embree
    have started theirs could hang in the child), or `at_once` when not parallel, not
    single-threaded, or no core is idle (the worker then only adds its overhead, ~0.7 s of CPU).
    `shared`: called first, here, for what it caches, which both processes need (else each makes it).
    Either way within `memory.settled`; the worker releases what each task leaves (`work.released`)."""
    if parallel and shared is not None:
        shared()  # before the checks: what it does must leave this process single-threaded to be forked
    with settled():
        if not (parallel and _single_threaded() and _idle_core()):
            yield at_once
            return
        with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
            pool.submit(int).result()  # the fork, now
            yield partial(pool.submit, released)


def _idle_core() -> bool:
    """True when fewer processes are running right now than there are cores (Linux's
    /proc/loadavg, this one included); False where it cannot tell."""
    try:
        running = int(Path("/proc/loadavg").read_text().split()[3].split("/")[0])
    except (OSError, IndexError, ValueError):
        return False
    return running < (os.cpu_count() or 1)


def _single_threaded() -> bool:
    """True when this process runs one thread (Linux's /proc/self/task); False where it cannot tell."""
    try:
        return len(os.listdir("/proc/self/task")) == 1
    except OSError:
        return False


def design_job(
    scan_path: str | Path, mask: str = "nasal", landmarks_path: str | Path | None = None, units: str = "auto",
    on_stage: Callable[[str], None] = _silent, parallel: bool = False, stock: str | None = "best",
) -> tuple[DesignRun, dict[str, bytes]]:
    """`cpapfit design`: read the scan (and landmarks), design, build the report; the run and its
    files {name: bytes} (with fused_scan.ply for a sweep or a RealSense recording). `parallel`: the
    stock sizes, the solids' files (checked as read back) and some report pictures made in a second
    process (`worker`; the stock family's population, which both processes need, made first). What a
    stage leaves is released as the next starts (`memory.release`). The report is imported before the
    worker is forked, so that both processes have it (and it is frozen with the rest, `memory.settled`)."""
    import_module(".report.assemble", __package__)  # imported where used by `outputs`, which `register` never uses
    on_stage = _releasing(on_stage)
    with worker(parallel, population if stock else None) as submit:
        on_stage("reading the scan")
        scan = load_scan(Path(scan_path), units)
        handed = []  # the solids' files, checked while the best stock size is pressed asleep and the report drawn
        d = design(scan, mask, user_landmarks(landmarks_path, scan), on_stage=on_stage, submit=submit, stock=stock,
                   solids_made=lambda *solids: handed.append(submit(solid_files, *solids)))
        solids = handed[0] if handed else submit(solid_files, d.solid, d.mould_parts, d.frame.mesh)
        if solids.done():
            solids.result()  # checked already (no worker): a solid that fails stops the design here
        records = record_files(d, scan)
        on_stage("report")
        pictures = report_files(d, scan, records, submit)
        files = in_order(records, solids.result())
        if is_fused(Path(scan_path)):
            files["fused_scan.ply"] = fused_ply(scan)
        files |= pictures
    return DesignRun(json.loads(files["fit.json"]), scan.units_note, tuple(files), d), files


def _releasing(on_stage: Callable[[str], None]) -> Callable[[str], None]:
    """`on_stage` with the memory the last stage left released first."""
    def announce(stage: str) -> None:
        release()
        on_stage(stage)
    return announce


@dataclass(frozen=True)
class ScanTask:
    """One scan of a batch: the scan (mesh file or capture folder), its output folder
    OUT_DIR/<name>, and the design parameters."""

    scan: Path
    out: Path
    mask: str = "nasal"
    units: str = "auto"
    stock: str | None = "best"  # the stock cushion to compare with (`pipeline.design`)


@dataclass(frozen=True)
class ScanResult:
    """One row of a batch summary. status: "designed", "unchanged" (outputs kept from an earlier
    run) or "failed" (with `error`). seconds: time spent on the scan in this run (None when its
    worker was lost). leak (L/min),
    window fraction (0-1) and warnings come from fit.json; None or empty where fit.json has none."""

    name: str
    status: str
    seconds: float | None
    leak_l_min: float | None = None
    window_fraction: float | None = None
    warnings: tuple[str, ...] = ()
    error: str = ""


def scan_inputs(scan: Path) -> list[Path]:
    """Every file a scan is read from: a capture folder's files, or a mesh file and its companions."""
    if scan.is_dir():
        return sorted(p for p in scan.rglob("*") if p.is_file())
    return [scan, *companion_files(scan)]


def content_hash(task: ScanTask) -> str:
    """SHA-256 of the cpapfit version, the parameters and every input file (name, size, bytes)."""
    h = hashlib.sha256(json_bytes({"cpapfit": __version__, "mask": task.mask, "units": task.units, "stock": task.stock}))
    for path in scan_inputs(task.scan):
        data = path.read_bytes()
        h.update(f"{os.path.relpath(path, task.scan.parent)}\0{len(data)}\0".encode())
        h.update(data)
    return h.hexdigest()


def run_scan(task: ScanTask) -> ScanResult:
    """The batch task: skip a scan whose outputs match its content hash, else design it into a
    staging folder renamed into place. Never raises: a failure is a row with its error message,
    and leaves no outputs for the scan (stale ones from an earlier input are removed)."""
    start = time.perf_counter()
    try:
        with _clearing(task.out):
            digest = content_hash(task)
            kept = _kept_fit(task.out, digest)
            fit = kept if kept is not None else _build(task, digest, start)
        return _result(task.out.name, "unchanged" if kept is not None else "designed", fit, time.perf_counter() - start)
    except Exception as exc:  # one scan's failure, whatever it is, is its row and never the batch's end
        message = str(exc) if isinstance(exc, CpapfitError) else f"internal error {type(exc).__name__}: {exc}"
        return ScanResult(task.out.name, "failed", time.perf_counter() - start, error=message)


def _result(name: str, status: str, fit: dict, seconds: float) -> ScanResult:
    """A summary row from fit.json's leak, window fraction and warnings, where present."""
    custom = fit.get("custom", {})
    warnings = [w["message"] for w in fit.get("warnings", [])] + (["rescan advised"] if fit.get("rescan_advised") else [])
    return ScanResult(name, status, seconds, custom.get("leak_l_min"), custom.get("window_fraction"), tuple(warnings))


def _owned(folder: Path) -> bool:
    """True when `folder` was made by cpapfit design or batch (it has a manifest)."""
    return (folder / MANIFEST).is_file()


def _kept_fit(folder: Path, digest: str) -> dict | None:
    """fit.json of earlier outputs made from the same content hash and still complete, or None."""
    try:
        manifest = json.loads((folder / MANIFEST).read_text())
        complete = manifest["hash"] == digest and all((folder / name).is_file() for name in manifest["files"])
        return json.loads((folder / "fit.json").read_text()) if complete else None
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _build(task: ScanTask, digest: str, start: float) -> dict:
    """The batch's design of `task` into its folder, its manifest stamped with the content hash and the time; the fit."""
    return _design_folder(task, lambda: {"hash": digest, "seconds": round(time.perf_counter() - start, 2)}).fit


def design_folder(task: ScanTask, landmarks_path: str | Path | None = None, on_stage: Callable[[str], None] = _silent,
                  parallel: bool = False) -> DesignRun:
    """`cpapfit design`: `task` designed into its folder as one set, which then holds this scan's
    complete outputs (`manifest.json` lists them) or, on any failure, nothing of an earlier design."""
    with _clearing(task.out):
        return _design_folder(task, dict, landmarks_path, on_stage, parallel)


def _design_folder(task: ScanTask, stamp: Callable[[], dict], landmarks_path=None, on_stage=_silent, parallel=False) -> DesignRun:
    """Design `task`, then `save_folder` its files with the manifest (and `stamp()`)."""
    _check_folder(task.out)
    run, files = design_job(task.scan, task.mask, landmarks_path, task.units, on_stage, parallel, task.stock)
    on_stage("writing files")
    landmarks = None if landmarks_path is None else str(landmarks_path)
    save_folder(task.out, files, manifest_record(task, run.files, landmarks, stamp()))
    return run


def save_folder(folder: Path, files: dict[str, bytes], manifest: dict) -> None:
    """`files` {name: bytes} and then `manifest` (manifest.json) written into a hidden staging folder
    renamed into place of `folder`, which must be new, empty or an earlier cpapfit design: the
    folder holds the whole set or, if anything fails, what it held before."""
    _check_folder(folder)
    staging = _hidden(folder, "tmp")
    staging.mkdir(parents=True)
    try:
        write_files(staging, files)
        write_bytes(staging / MANIFEST, json_bytes(manifest))
        _replace_folder(staging, folder)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _check_folder(folder: Path) -> None:
    """InputError unless `folder` is new, empty or an earlier cpapfit design (it will be replaced)."""
    if folder.exists() and not (_owned(folder) or _empty_folder(folder)):
        raise InputError(f"{folder}: exists and is not a cpapfit design folder (no {MANIFEST}); move it away or choose another --out")


@contextlib.contextmanager
def _clearing(folder: Path):
    """On a failure inside, an earlier cpapfit design in `folder` is removed (and the error notes it),
    so that it cannot be taken for the design of the scan that failed."""
    try:
        yield
    except Exception as exc:
        if _owned(folder):
            shutil.rmtree(folder)
            exc.add_note(f"(the earlier design in {folder} was removed, so that it cannot be taken for this run's)")
        raise


def _empty_folder(path: Path) -> bool:
    return path.is_dir() and not any(path.iterdir())


def _hidden(folder: Path, kind: str) -> Path:
    """A fresh hidden sibling of `folder` for staging ("tmp") or for the outputs it replaces ("old")."""
    folder = folder.absolute()
    return folder.with_name(f".{folder.name}.{kind}-{uuid.uuid4().hex[:8]}")


def _replace_folder(new: Path, folder: Path) -> None:
    """Put `new` in place of `folder` by renames; a kill in between leaves only hidden folders."""
    old = _hidden(folder, "old")
    if folder.exists():
        os.rename(folder, old)
    os.rename(new, folder)
    shutil.rmtree(old, ignore_errors=True)


def clean_leftovers(out_dir: Path) -> None:
    """Remove the hidden staging folders and files a killed run left in `out_dir`."""
    for path in [p for p in Path(out_dir).glob(".*") if LEFTOVER.match(p.name)]:
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink()
