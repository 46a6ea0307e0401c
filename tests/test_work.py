"""Work shared between a worker process and this one (`cpapfit.work`)."""

import multiprocessing
import os
import pickle
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest
import trimesh

from cpapfit.evaluation.fit import Face
from cpapfit.io import load_scan
from cpapfit.pipeline import design
from cpapfit.work import Again, Shared, at_once


def _job(seconds: float, value: int) -> tuple[int, int]:
    """(value squared, the pid that did it), after `seconds` asleep."""
    time.sleep(seconds)
    return value * value, os.getpid()


def test_shared_work_the_worker_busy_leaves_the_rest_to_this_process_from_the_last():
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        pool.submit(int).result()  # the worker forked
        shared = Shared(pool.submit, _job, [(1.0, 0), (0.0, 1), (0.0, 2), (0.0, 3)])
        out = shared.results()
    assert [value for value, _ in out] == [0, 1, 4, 9]
    assert out[0][1] != os.getpid()  # the one the worker was handed
    assert [pid for _, pid in out[1:]] == [os.getpid()] * 3  # not queued ahead in the pool: done here


def _marked(path: Path, value: int) -> tuple[int, int]:
    """`_job` at once, leaving a file named after `value` in `path` when done."""
    out = _job(0.0, value)
    (path / str(value)).touch()
    return out


def test_shared_work_handed_on_as_each_is_done(tmp_path):
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        pool.submit(int).result()
        shared = Shared(pool.submit, _marked, [(tmp_path, v) for v in range(4)])
        for _ in range(600):  # the worker takes each in turn meanwhile
            if len(list(tmp_path.iterdir())) == 4:
                break
            time.sleep(0.05)
        out = shared.results()
    assert [value for value, _ in out] == [0, 1, 4, 9]
    assert all(pid != os.getpid() for _, pid in out)


def test_shared_work_at_once_is_done_in_order_as_it_is_made():
    done = []
    shared = Shared(at_once, lambda v: done.append(v) or -v, [(v,) for v in range(3)])
    assert done == [0, 1, 2]
    assert shared.results() == shared.results() == [0, -1, -2]


def _stepped(order: list | None, value: int, seconds: float, *steps: int):
    """A job of two steps: the first (`seconds` asleep) says `Again` with the pid that did it; the
    second returns (value squared, both steps' pids). Each step is noted in `order` (at once)."""
    if order is not None:
        order.append((value, len(steps)))
    if not steps:
        time.sleep(seconds)
        return Again((os.getpid(),))
    return value * value, steps[0], os.getpid()


def test_shared_work_in_steps_takes_every_first_step_before_any_next():
    order = []
    out = Shared(at_once, _stepped, [(order, v, 0.0) for v in range(3)]).results()
    assert order == [(0, 0), (1, 0), (2, 0), (0, 1), (1, 1), (2, 1)]
    assert out == [(v * v, os.getpid(), os.getpid()) for v in range(3)]


def test_a_step_gets_the_jobs_own_args_and_the_last_agains_only():
    """A job of three steps: each step after the first is called with the job's args followed by the
    args of the `Again` the step before it returned, not those of every earlier step."""

    def three(value: int, *passed: int):
        return Again((len(passed) + 1,)) if passed in ((), (1,)) else (value, passed)

    assert Shared(at_once, three, [(v,) for v in range(3)]).results() == [(v, (2,)) for v in range(3)]


def test_shared_work_in_steps_between_the_worker_and_this_process():
    """Each job's steps done once, by either process, its result the last step's; the worker's
    first step outlasts this process's three, whose next steps this process takes at once."""
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork")) as pool:
        pool.submit(int).result()
        out = Shared(pool.submit, _stepped, [(None, 0, 1.0)] + [(None, v, 0.0) for v in (1, 2, 3)]).results()
    assert [value for value, *_ in out] == [0, 1, 4, 9]
    assert out[0][1] != os.getpid()
    assert [o[1:] for o in out[1:]] == [(os.getpid(), os.getpid())] * 3


def test_a_face_goes_to_a_worker_as_its_arrays_not_its_meshes_caches():
    """A process pool pickles what it is handed in a thread of its own while this process goes on
    filling the face's meshes' caches: the face must pickle as its meshes' arrays alone (a cache
    growing while pickled stopped a design with "dictionary changed size during iteration"), and
    its meshes come back with their normals (the same to the bit) and no other cache."""
    mesh = trimesh.creation.icosphere(2)
    face = Face(mesh, mesh.copy(), np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]))
    face.registered.kdtree, face.scan.triangles_tree  # caches filled, as a design's first queries fill them
    for sent in (face, Face(trimesh.PointCloud(mesh.vertices), mesh, face.axis, face.up)):
        back = pickle.loads(pickle.dumps(sent))
        for mesh_back, mesh_sent in ((back.scan, sent.scan), (back.registered, sent.registered)):
            if isinstance(mesh_sent, trimesh.Trimesh):
                assert set(mesh_back._cache.cache) == {"face_normals", "vertex_normals"}
                assert np.array_equal(mesh_back.vertex_normals, mesh_sent.vertex_normals)
            else:
                assert not mesh_back._cache.cache
        assert type(back.scan) is type(sent.scan) and np.array_equal(back.scan.vertices, sent.scan.vertices)
        assert np.array_equal(back.registered.faces, sent.registered.faces) and np.array_equal(back.axis, sent.axis)


def test_the_stock_sizes_seated_here_are_a_stage_of_their_own(placed1, phantom1_dir):
    """With no worker the stock sizes are seated as the custom cushion's contact is judged:
    `--verbose` times them as a stage of their own, not as the cushion's (the design stopped as its
    solid begins)."""

    class Stop(Exception):
        pass

    def on_stage(name: str) -> None:
        stages.append(name)
        if name == "solid and checks":
            raise Stop

    stages = []
    with pytest.raises(Stop):
        design(load_scan(phantom1_dir), "nasal", on_stage=on_stage, placement=placed1, stock="M")
    assert stages[stages.index("cushion") + 1 :] == ["the stock sizes, each at its best seat", "solid and checks"]
