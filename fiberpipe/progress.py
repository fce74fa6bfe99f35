"""Progress bars of the long commands (a leaf module): a rich bar on a terminal, nothing in CI or
logs, where the commands' own summary lines say what was done."""

from __future__ import annotations

import sys
from contextlib import contextmanager


def terminal_bar(label: str):
    """``update(done, total, *more)``, drawing a transient rich progress bar labelled ``label`` while
    standard error is a terminal; None otherwise. ``update.close()`` removes the bar. Further
    arguments are ignored, so the bar is also the solver's ``progress(t_s, end_time_s, steps)``."""
    if not sys.stderr.isatty():
        return None
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    state = {}

    def update(done: float, total: float, *_more) -> None:
        if "bar" not in state:
            bar = Progress(TextColumn(label), BarColumn(), TextColumn("{task.percentage:>5.1f}%"), TimeRemainingColumn(),
                           transient=True)
            bar.start()
            state["bar"] = bar
            state["task"] = bar.add_task(label, total=total)
        state["bar"].update(state["task"], completed=min(done, total))

    def close() -> None:
        if "bar" in state:
            state["bar"].stop()

    update.close = close
    return update


@contextmanager
def progress_bar(label: str, enabled: bool = True):
    """:func:`terminal_bar` for a ``with`` block (None unless ``enabled`` and on a terminal), closed
    when the block ends, however it ends."""
    bar = terminal_bar(label) if enabled else None
    try:
        yield bar
    finally:
        if bar is not None:
            bar.close()
