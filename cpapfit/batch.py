"""Many scans on Dask: every scan in a folder through `design`, on a local cluster of worker
processes (one per core by default) or on a running cluster (`scheduler` address).

Tasks are independent and idempotent (`jobs.run_scan`): a scan whose content hash matches its
outputs is skipped, a failure is a row and never stops the batch, a rerun retries failures.
Workers read the scans and write the outputs themselves, so on several machines INPUT_DIR and
OUT_DIR must be on a file system every worker sees at the same path.
"""

import contextlib
import logging
import os
from collections import Counter
from pathlib import Path
from typing import Callable, Iterator

import dask
from distributed import Client, LocalCluster, as_completed

from .errors import InputError
from .io.mesh import MESH_SUFFIXES
from .io.rsbag import BAG_SUFFIX
from .jobs import ScanResult, ScanTask, clean_leftovers, run_scan

CONNECT_TIMEOUT_S = 10  # to reach a scheduler, and for it to have a worker
# Dask's nanny starts its workers with MALLOC_TRIM_THRESHOLD_ set, which pins glibc's mmap threshold
# at its 128 kB floor: every array over it is mapped afresh and its pages faulted in again, and a
# design costs 1.3-1.5 times the CPU, over a quarter of it in the kernel (bench/RESULTS.md section
# 6). A design hands its memory back itself between stages (`memory.release`): the local cluster's
# workers start without it.
WORKER_ENVIRON = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}


def find_scans(input_dir: Path, out_dir: Path) -> tuple[dict[str, Path], list[str]]:
    """The scans in `input_dir` by output folder name (mesh files, capture folders, sweeps and
    RealSense recordings; hidden entries and `out_dir` left out), and the names of the other
    entries (not scans)."""
    if not input_dir.is_dir():
        raise InputError(f"{input_dir}: no such folder; INPUT_DIR is a folder of scans (mesh files, capture folders)")
    inp, out = input_dir.resolve(), out_dir.resolve()
    if out == inp or (out.is_relative_to(inp) and out.parent != inp):
        raise InputError(f"{out_dir}: the output folder must be neither the input folder nor inside a scan in it")
    entries = sorted(p for p in input_dir.iterdir() if not p.name.startswith(".") and p.resolve() != out)
    scans = [p for p in entries if p.is_dir() or p.suffix.lower() in (*MESH_SUFFIXES, BAG_SUFFIX)]
    if not scans:
        raise InputError(f"{input_dir}: no scans in it (mesh files {' '.join(MESH_SUFFIXES)}, RGB-D capture folders, sweeps or {BAG_SUFFIX} recordings)")
    return scan_names(scans), [p.name for p in entries if p not in scans]


def scan_names(scans: list[Path]) -> dict[str, Path]:
    """Each scan by its output folder name: a folder's name, a file's stem, or the file's full name
    where two scans would share one."""
    short = {p: p.name if p.is_dir() else p.stem for p in scans}
    count = Counter(short.values())
    return {short[p] if count[short[p]] == 1 else p.name: p for p in scans}


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Client]:
    """A client of the running cluster at `scheduler`, or of a new local cluster of `workers` worker
    processes (default: one per core) with one thread each (Dask's nanny also sets the numeric
    libraries' threads to 1 in each worker; `WORKER_ENVIRON`)."""
    if not scheduler:
        with dask.config.set(WORKER_ENVIRON):
            cluster = LocalCluster(
                n_workers=workers or os.cpu_count(), threads_per_worker=1, processes=True,
                dashboard_address=None, silence_logs=logging.CRITICAL,  # failures are rows of the summary
            )
        with cluster, Client(cluster) as client:
            yield client
        return
    try:
        client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(f"cannot reach a Dask scheduler at {scheduler} ({exc}); start one with `dask scheduler`") from None
    with client:
        try:
            client.wait_for_workers(1, timeout=CONNECT_TIMEOUT_S)
        except TimeoutError:
            raise InputError(f"the Dask scheduler at {scheduler} has no workers; start some with `dask worker {scheduler}`") from None
        yield client


def run_batch(
    scans: dict[str, Path], out_dir: Path, mask: str = "nasal", workers: int | None = None,
    scheduler: str | None = None, on_result: Callable[[ScanResult], None] = lambda row: None, stock: str | None = "best",
) -> list[ScanResult]:
    """Every scan through `design` on a Dask cluster, outputs in `out_dir`/<name>; the rows in name
    order. Leftovers of a killed run are removed first; `on_result(row)` is called as each scan ends.
    `stock`: the stock cushion each design is compared with (`pipeline.design`)."""
    clean_leftovers(out_dir)
    tasks = [ScanTask(path.resolve(), (out_dir / name).resolve(), mask, stock=stock) for name, path in scans.items()]
    rows = []
    with dask_client(workers, scheduler) as client:
        futures = {client.submit(run_scan, task, pure=False): task for task in tasks}
        for future in as_completed(futures):
            rows.append(_collect(future, futures[future]))
            on_result(rows[-1])
    return sorted(rows, key=lambda row: row.name)


def _collect(future, task: ScanTask) -> ScanResult:
    """The row a task returned, or a failed row when its worker died (run_scan itself never raises)."""
    try:
        return future.result()
    except Exception as exc:  # a worker killed or lost during the scan: that scan's row, not the batch's end
        return ScanResult(task.out.name, "failed", None, error=f"worker lost ({type(exc).__name__}: {exc})")
