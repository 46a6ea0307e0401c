"""Work handed out: `submit(fn, *args)` is a worker process's (see `jobs.worker`) or `at_once`'s.
Either way a future whose result() is fn(*args), so stages run the same with and without a worker."""

import threading
from concurrent.futures import Future

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


class Shared:
    """fn(*args) for each of `jobs`, shared between `submit`'s worker and this process: the worker
    is handed them one at a time from the first, each when its last is done (a process pool queues
    ahead what it is handed, where it can no longer be taken back), and `results` does here the
    ones not yet handed out, from the last."""

    def __init__(self, submit, fn, jobs):
        self._submit, self._fn = submit, fn
        self._todo = list(enumerate(jobs))
        self._handed: dict[int, Future] = {}
        self._here: dict[int, object] = {}
        self._lock = threading.Lock()
        self._hand_on()

    def _hand_on(self, _done: Future | None = None) -> None:
        """Hand the worker the first job not yet begun (called again as each it was handed is done)."""
        with self._lock:
            if not self._todo:
                return
            i, args = self._todo.pop(0)
            try:
                self._handed[i] = future = self._submit(self._fn, *args)
            except Exception:  # no worker to take it (a broken pool): `results` does it here
                self._todo.insert(0, (i, args))
                return
        future.add_done_callback(self._hand_on)

    def results(self) -> list:
        """Every job's fn(*args), in order; the worker's exceptions are raised here."""
        while True:
            with self._lock:
                if not self._todo:
                    break
                i, args = self._todo.pop()
            self._here[i] = self._fn(*args)
        return [self._here[i] if i in self._here else self._handed[i].result() for i in range(len(self._here) + len(self._handed))]
