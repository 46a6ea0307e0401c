"""Work handed out: `submit(fn, *args)` is a worker process's (see `jobs.worker`) or `at_once`'s.
Either way a future whose result() is fn(*args), so stages run the same with and without a worker."""

from concurrent.futures import Future


def at_once(fn, *args) -> Future:
    """fn(*args) run here and now, as a finished future (an exception is raised by result())."""
    done = Future()
    try:
        done.set_result(fn(*args))
    except Exception as exc:
        done.set_exception(exc)
    return done


def ahead(submit, fn, *args) -> None:
    """fn(*args) started now by `submit`'s worker, for what it caches there; nothing when `submit` is
    `at_once` (done here, it would only be done sooner, not faster, and for nothing if the run stops)."""
    if submit is not at_once:
        submit(fn, *args)
