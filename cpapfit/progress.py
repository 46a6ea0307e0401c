"""Progress on a terminal: the running stage with a spinner (rich), on stderr.

Quiet when stderr is not a terminal or with --quiet; --verbose adds each stage's time.
"""

import contextlib
import time

from rich.console import Console


@contextlib.contextmanager
def stage_display(quiet: bool = False, verbose: bool = False):
    """Yield an `on_stage(name)` callback that shows the current stage and, if verbose, timings."""
    console = Console(stderr=True)
    live = console.is_terminal and not quiet
    state = {"name": None, "start": time.perf_counter()}

    def finish() -> None:
        if state["name"] and verbose:
            console.print(f"  {state['name']}: {time.perf_counter() - state['start']:.2f} s", highlight=False)

    with console.status("", spinner="dots") if live else contextlib.nullcontext() as status:

        def on_stage(name: str) -> None:
            finish()
            state["name"], state["start"] = name, time.perf_counter()
            if status is not None:
                status.update(f"{name} ...")

        yield on_stage
        finish()
