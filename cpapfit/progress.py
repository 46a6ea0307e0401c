"""Progress on a terminal, on stderr (rich): the running stage of a design with a spinner, or a
bar across a batch. Quiet when stderr is not a terminal or with --quiet; --verbose adds each
stage's time.
"""

import contextlib
import time

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn


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


@contextlib.contextmanager
def batch_display(total: int, quiet: bool = False):
    """Yield an `advance(text)` callback: one scan of `total` done, `text` says which and how."""
    console = Console(stderr=True)
    if quiet or not console.is_terminal:
        yield lambda text: None
        return
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn())
    with Progress(*columns, console=console) as progress:
        task = progress.add_task("designing scans", total=total)
        yield lambda text: progress.update(task, advance=1, description=text)
