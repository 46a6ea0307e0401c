"""cpapfit batch: scans designed on a Dask cluster of worker processes, a failed scan is a row,
a rerun skips what is unchanged and retries failures, a killed run leaves nothing half-written."""

import contextlib
import csv
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest
import trimesh
from distributed import LocalCluster

from records import written
from cpapfit.batch import dask_client, find_scans
from cpapfit.cli import main
from cpapfit.io.phantom import write_phantom
from cpapfit.io.summary import summary_csv, summary_html
from cpapfit.jobs import ScanTask, content_hash, run_scan
from cpapfit.synthetic.template_phantom import make_phantom
from test_cli import assert_one_line_error

KILL_AFTER_S = 10.0  # into the rerun: past its start-up, well inside p2's design


@pytest.fixture(scope="module")
def phantoms(tmp_path_factory, phantom1_dir):
    """Two synthetic capture folders, p1 and p2."""
    folder = tmp_path_factory.mktemp("phantoms")
    shutil.copytree(phantom1_dir, folder / "p1")
    write_phantom(make_phantom(2), folder / "p2")
    return folder


def scans_folder(phantoms, folder):
    """A batch input: copies of p1 and p2."""
    shutil.copytree(phantoms, folder)
    return folder


def summary(out):
    with open(out / "summary.csv", newline="") as fh:
        return {row["scan"]: row for row in csv.DictReader(fh)}


def stamps(out, names):
    """(inode, mtime in ns) of each scan's manifest."""
    return {n: ((st := os.stat(out / n / "manifest.json")).st_ino, st.st_mtime_ns) for n in names}


def thread_cluster() -> LocalCluster:
    """A running scheduler on TCP, as a user's is, with one worker thread in this process (no worker
    process to start, the stages' caches warm; no memory limit, which would read this whole process):
    the batches run on it after the first."""
    return LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://", memory_limit=0, dashboard_address=None)


def hidden(out):
    return sorted(p.name for p in out.iterdir() if p.name.startswith("."))


@pytest.fixture(scope="module")
def batched(phantoms, tmp_path_factory):
    """p1, p2, a bad file and a note batched on a local cluster of two workers: (input, output, exit code, stderr)."""
    folder = tmp_path_factory.mktemp("batched")
    inp, out = scans_folder(phantoms, folder / "in"), folder / "out"
    (inp / "bad.ply").write_bytes(b"ply\nthis is no mesh\n")
    (inp / "notes.txt").write_text("not a scan")
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["batch", str(inp), "--out", str(out), "--workers", "2", "--stock", "none"])
    return inp, out, code, err.getvalue()


def test_batch_on_a_local_cluster_with_a_bad_file_then_rerun_on_a_running_scheduler(cli, batched, tmp_path):
    batch_inp, batch_out, code, err = batched
    inp, out = shutil.copytree(batch_inp, tmp_path / "in"), shutil.copytree(batch_out, tmp_path / "out")
    assert code == 1, err  # some failed
    rows = summary(out)
    assert sorted(rows) == ["bad", "p1", "p2"]  # notes.txt is no scan
    assert rows["bad"]["status"] == "failed" and "bad.ply" in rows["bad"]["error"] and "not a readable PLY" in rows["bad"]["error"]
    assert "bad.ply" in err and "3 scans: 2 designed, 0 unchanged, 1 failed" in err and "Traceback" not in err
    for name in ("p1", "p2"):
        assert rows[name]["status"] == "designed" and rows[name]["error"] == "" and float(rows[name]["time (s)"]) > 1
        manifest = written(out / name / "manifest.json")
        assert manifest["hash"] == content_hash(ScanTask(inp / name, out / name, "nasal", stock=None))
        assert manifest["parameters"]["stock"] is None and "stock_fitting" not in written(out / name / "fit.json")
        assert all((out / name / f).stat().st_size > 0 for f in manifest["files"])
        assert written(out / name / "fit.json")["mask"] == "nasal"
        assert trimesh.load(out / name / "cushion.stl").is_watertight
    assert not (out / "bad").exists() and hidden(out) == []
    page = (out / "batch_report.html").read_text()
    assert "<th>time (s)</th>" in page and "<th>leak (L/min)</th>" in page and page.count("<tr class=") == 3
    assert "http" not in page and "<script" not in page  # self-contained, offline

    before = stamps(out, ["p1", "p2"])
    (inp / "bad.ply").write_bytes(b"")  # still bad, differently: a retry gives the new error
    with thread_cluster() as cluster:
        code, _, err = cli("batch", inp, "--out", out, "--scheduler", cluster.scheduler_address, "--stock", "none")
    assert code == 1, err
    rows = summary(out)
    assert [rows[n]["status"] for n in ("bad", "p1", "p2")] == ["failed", "unchanged", "unchanged"]
    assert "the file is empty" in rows["bad"]["error"]
    assert stamps(out, ["p1", "p2"]) == before  # not redone


def test_a_killed_rerun_leaves_the_earlier_design_and_the_next_redoes_only_what_was_unfinished(cli, batched, tmp_path):
    """A rerun after p2's input changed is killed while it designs p2 (KILL_AFTER_S in, or as its
    staging folder appears, whichever is first: the folder is written in well under a second at the
    end of a ~20 s design, too short a window to aim at alone): p2's folder still holds the earlier
    design, whole; the run after redoes p2 alone."""
    batch_inp, batch_out, _, _ = batched
    inp, out, log = tmp_path / "in", shutil.copytree(batch_out, tmp_path / "out"), tmp_path / "stderr.txt"
    for name in ("p1", "p2"):
        shutil.copytree(batch_inp / name, inp / name)
    with open(inp / "p2" / "intrinsics.json", "a") as fh:
        fh.write("\n")  # other bytes, the same scan: p2 is designed again
    earlier = written(out / "p2" / "manifest.json")
    command = [sys.executable, "-m", "cpapfit", "batch", str(inp), "--out", str(out), "--workers", "1", "--stock", "none", "--quiet"]
    with open(log, "w") as stderr:
        proc = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=stderr)
    try:
        start = time.monotonic()
        while not hidden(out) and time.monotonic() - start < KILL_AFTER_S:  # p2 under way
            assert proc.poll() is None, log.read_text()
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the batch and its worker processes
        proc.wait()
    assert written(out / "p2" / "manifest.json") == earlier and all((out / "p2" / f).is_file() for f in earlier["files"])
    before = stamps(out, ["p1"])

    with thread_cluster() as cluster:
        code, _, err = cli("batch", inp, "--out", out, "--scheduler", cluster.scheduler_address, "--stock", "none")
    assert code == 0, err
    rows = summary(out)
    assert rows["p1"]["status"] == "unchanged" and rows["p2"]["status"] == "designed"
    assert stamps(out, ["p1"]) == before
    assert hidden(out) == [] and written(out / "p2" / "manifest.json")["hash"] == content_hash(ScanTask(inp / "p2", out / "p2", stock=None))


def test_content_hash_follows_bytes_parameters_and_an_obj_texture(tmp_path):
    scan = tmp_path / "face.obj"
    scan.write_text("mtllib face.mtl\nv 0 0 0\n")
    (tmp_path / "face.mtl").write_text("newmtl skin\nmap_Kd skin.png\n")
    (tmp_path / "skin.png").write_bytes(b"one")
    task = ScanTask(scan, tmp_path / "out" / "face")
    first = content_hash(task)
    assert content_hash(task) == first
    assert content_hash(ScanTask(scan, tmp_path / "out" / "face", mask="oronasal")) != first
    assert content_hash(ScanTask(scan, tmp_path / "out" / "face", stock=None)) != first  # another comparison, another design
    (tmp_path / "skin.png").write_bytes(b"two")
    assert content_hash(task) != first


def test_kept_outputs_give_their_fit_numbers_and_changed_input_that_fails_removes_them(tmp_path):
    scan = tmp_path / "face.ply"
    scan.write_text("ply\nnot really\n")
    task = ScanTask(scan, tmp_path / "out" / "face")
    task.out.mkdir(parents=True)
    fit = {"custom": {"leak_l_min": 1.234, "window_fraction": 0.875}, "warnings": [{"code": "hole_mm", "message": "thin bridge"}],
           "rescan_advised": True}
    (task.out / "fit.json").write_text(json.dumps(fit))
    (task.out / "manifest.json").write_text(json.dumps({"hash": content_hash(task), "files": ["fit.json"]}))
    row = run_scan(task)
    assert (row.status, row.leak_l_min, row.window_fraction, row.warnings) == ("unchanged", 1.234, 0.875, ("thin bridge", "rescan advised"))
    assert "face,unchanged,0.0,1.23,0.875,thin bridge; rescan advised," in summary_csv([row]).decode()
    assert "<td>1.23</td><td>0.875</td>" in summary_html([row], "nasal").decode()

    scan.write_text("ply\nchanged, still not a mesh\n")
    row = run_scan(task)
    assert row.status == "failed" and "face.ply" in row.error and row.leak_l_min is None
    assert ",failed," in summary_csv([row]).decode() and not task.out.exists()


def test_local_workers_keep_glibcs_own_memory_thresholds(monkeypatch):
    """The local cluster's worker processes start without Dask's MALLOC_TRIM_THRESHOLD_ (which pins
    glibc's mmap threshold: a design takes 1.3-1.5 times the CPU), with the numeric libraries on one
    thread as Dask sets them (unless this process's environment says otherwise)."""
    monkeypatch.delenv("MALLOC_TRIM_THRESHOLD_", raising=False)
    with dask_client(workers=1) as client:
        (environ,) = client.run(lambda: {k: os.environ.get(k) for k in ("MALLOC_TRIM_THRESHOLD_", "OPENBLAS_NUM_THREADS")}).values()
    assert environ == {"MALLOC_TRIM_THRESHOLD_": None, "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1")}


def test_scans_found_and_named(tmp_path):
    inp = tmp_path / "in"
    for name in ("a.ply", "a.obj", "b.STL", "readme.txt", ".hidden.ply"):
        (inp / name).parent.mkdir(exist_ok=True)
        (inp / name).write_text("x")
    (inp / "capture").mkdir()
    (inp / "results").mkdir()
    scans, others = find_scans(inp, inp / "results")
    assert {n: p.name for n, p in scans.items()} == {"a.obj": "a.obj", "a.ply": "a.ply", "b": "b.STL", "capture": "capture"}
    assert others == ["readme.txt"]


def test_batch_user_errors(cli, tmp_path):
    assert_one_line_error(*cli("batch", tmp_path / "nope", "--out", tmp_path / "out"), "no such folder")
    (tmp_path / "empty").mkdir()
    assert_one_line_error(*cli("batch", tmp_path / "empty", "--out", tmp_path / "out"), "no scans")
    (tmp_path / "empty" / "a.ply").write_text("x")
    assert_one_line_error(*cli("batch", tmp_path / "empty", "--out", tmp_path / "empty"), "output folder")
    assert_one_line_error(*cli("batch", tmp_path / "empty", "--out", tmp_path / "out", "--workers", 0), "--workers")
    assert not (tmp_path / "out").exists()
