"""Work handed out: `submit(fn, *args)` is a worker process's (see `jobs.worker`) or `at_once`'s.
Either way a future whose result() is fn(*args), so stages run the same with and without a worker."""

import threading
from concurrent.futures import Future
from dataclasses import dataclass
from functools import partial

from .memory import release


def at_once(fn, *args) -> Future:
    """fn(*args) run here and now, as a finished future (an exception is raised by result())."""
    done = Future()
    try:
        done.set_result(fn(*args))
    except Exception as exc:
        done.set_exception(exc)
    return done


def released(fn, *args):
    """fn(*args), then the memory it left released (`memory.release`): a worker's tasks each take
    their own copy of what they are handed (a face, its indexes built again), which would pile up."""
    try:
        return fn(*args)
    finally:
        release()


def ahead(submit, fn, *args) -> None:
    """fn(*args) started now by `submit`'s worker, for what it caches there; nothing when `submit` is
    `at_once` (done here, it would only be done sooner, not faster, and for nothing if the run stops)."""
    if submit is not at_once:
        submit(fn, *args)


@dataclass(frozen=True)
class Again:
    """What a job of `Shared` returns when it is not done: its fn is to be called again, with the
    job's own args followed by `args`, by whichever of the two processes is free first."""

    args: tuple


class Shared:
    """fn(*args) for each of `jobs`, shared between `submit`'s worker and this process: the worker
    is handed them one at a time from the first, each when its last is done (a process pool queues
    ahead what it is handed, where it can no longer be taken back), and `results` does here the
    ones not yet handed out, from the last. A job that returns `Again` goes on as a step queued
    last: the worker takes the others' first steps first, this process the later steps, so that
    the two finish together to within a step rather than a whole job."""

    def __init__(self, submit, fn, jobs):
        self._submit, self._fn, self._jobs = submit, fn, [tuple(args) for args in jobs]
        self._todo = list(enumerate(self._jobs))  # (job number, its step's args: the job's own, then its last `Again`'s)
        self._done: dict[int, Future] = {}
        self._handed = False  # the worker has a step, not yet back
        self._cond = threading.Condition()
        self._hand_on()

    def _hand_on(self) -> None:
        """Hand the worker the first step not yet begun, unless it has one."""
        with self._cond:
            if self._handed or not self._todo:
                return
            i, args = self._todo.pop(0)
            self._handed = True
        try:
            future = self._submit(self._fn, *args)
        except Exception:  # no worker to take it (a broken pool): `results` does it here
            with self._cond:
                self._todo.insert(0, (i, args))
                self._handed = False
                self._cond.notify_all()
            return
        future.add_done_callback(partial(self._back, i))

    def _back(self, i: int, future: Future) -> None:
        """The worker's step of job `i` done: kept, or its next step queued; the worker handed on."""
        with self._cond:
            self._handed = False
            self._settle(i, future)
        self._hand_on()

    def _settle(self, i: int, future: Future) -> None:
        """Job `i`'s step done as `future`: its result, or (`Again`) its next step queued last, with the
        job's own args followed by the `Again`'s."""
        with self._cond:
            more = None if future.cancelled() or future.exception() is not None else future.result()
            if isinstance(more, Again):
                self._todo.append((i, self._jobs[i] + more.args))
            else:
                self._done[i] = future
            self._cond.notify_all()

    def results(self) -> list:
        """Every job's fn(*args), in order; the worker's exceptions are raised here."""
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._todo or not self._handed)
                if not self._todo:
                    break
                i, args = self._todo.pop()
            self._settle(i, at_once(self._fn, *args))
        return [self._done[i].result() for i in range(len(self._jobs))]
