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
    with Progress(*columns, console=console, transient=False) as bar:
        task = bar.add_task("fit", total=total, rms="-", speed="-")
        start = {"t": None, "g": 0}

        def update(generation: int, total_now: int, rms: float) -> None:
            now = time.time()
            if start["t"] is None:  # the first chunk includes compilation: rate from here on
                start["t"], start["g"] = now, generation
                speed = "-"
            else:
                dt = max(now - start["t"], 1e-9)
                speed = f"{(generation - start['g']) / dt:,.0f}"
            bar.update(task, completed=generation, total=total_now, rms=f"{rms:.4g}", speed=speed)

        yield update
