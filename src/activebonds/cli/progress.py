"""A rich progress bar for long fits: generation, best RMS error, generations per second, ETA."""

from __future__ import annotations

import time
from contextlib import contextmanager

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


@contextmanager
def fit_progress(total: int, console: Console):
    """A progress bar that appears with the first finished chunk: input errors found before
    then stay a single line."""
    columns = (
        TextColumn("[bold]generation"),
        MofNCompleteColumn(),
        BarColumn(),
        TextColumn("best {task.fields[rms]} mm"),
        TextColumn("{task.fields[speed]} gen/s"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
    )
    bar = Progress(*columns, console=console, transient=False)
    state: dict = {"task": None, "t": None, "g": 0}

    def update(generation: int, total_now: int, rms: float) -> None:
        now = time.time()
        if state["task"] is None:
            bar.start()
            state["task"] = bar.add_task("fit", total=total_now, rms="-", speed="-")
        if state["t"] is None:  # the first chunk includes compilation: rate from here on
            state["t"], state["g"] = now, generation
            speed = "-"
        else:
            dt = max(now - state["t"], 1e-9)
            speed = f"{(generation - state['g']) / dt:,.0f}"
        bar.update(
            state["task"], completed=generation, total=total_now, rms=f"{rms:.4g}", speed=speed
        )

    try:
        yield update
    finally:
        if state["task"] is not None:
            bar.stop()


@contextmanager
def sweep_progress(total: int, console: Console):
    """A progress bar over a sweep's fits: fits done of all, how many were skipped (finished
    before) and how many failed, elapsed time, ETA. Yields ``update(outcome)``."""
    columns = (
        TextColumn("[bold]fits"),
        MofNCompleteColumn(),
        BarColumn(),
        TextColumn("{task.fields[skipped]} skipped, {task.fields[failed]} failed"),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
    )
    bar = Progress(*columns, console=console, transient=False)
    task = bar.add_task("sweep", total=total, skipped=0, failed=0)
    counts = {"skipped": 0, "failed": 0}

    def update(outcome) -> None:
        if outcome.action == "skipped":
            counts["skipped"] += 1
        if not outcome.ok:
            counts["failed"] += 1
        bar.update(task, advance=1, **counts)

    bar.start()
    try:
        yield update
    finally:
        bar.stop()
