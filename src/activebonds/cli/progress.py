"""What long commands show while they run: a fit's progress bar (generation, best RMS error,
generations per second, ETA) and status lines for its silent phases, a sweep's bar."""

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

DETAIL_SECONDS = 30.0  # a phase's detail line printed at most this often in a log


class FitProgress:
    """What a fit shows while it runs: ``progress(generation, total, rms)`` after each chunk
    (a bar on ``console``, from the first finished chunk, so input errors found before stay a
    single line) and ``progress.status(text)`` before a long silent phase (on ``status_console``:
    a spinner in a terminal, a plain line ``text ...`` otherwise). One live display at a time:
    a status stops the bar (which stays printed), the next chunk stops the status.
    ``on_update`` runs after each chunk's update (the command line's interrupt check)."""

    def __init__(self, total: int, console: Console, status_console: Console, on_update=None):
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
        self.bar = Progress(*columns, console=console, transient=False)
        self.status_console, self.on_update = status_console, on_update
        self.task = None
        self.t: float | None = None  # wall time of the first finished chunk
        self.g = 0
        self.spinner = None
        self.said = ""  # the status shown
        self.detail_at = 0.0  # when a phase's detail was last printed (a log)
        self.live = False  # the bar is shown

    def __call__(self, generation: int, total_now: int, rms: float) -> None:
        self._stop_spinner()
        now = time.time()
        if self.task is None:
            self.task = self.bar.add_task("fit", total=total_now, rms="-", speed="-")
        if not self.live:
            self.bar.start()
            self.live = True
        if self.t is None:  # the first chunk includes compilation: rate from here on
            self.t, self.g = now, generation
            speed = "-"
        else:
            speed = f"{(generation - self.g) / max(now - self.t, 1e-9):,.0f}"
        self.bar.update(
            self.task, completed=generation, total=total_now, rms=f"{rms:.4g}", speed=speed
        )
        if self.on_update is not None:
            self.on_update()

    def status(self, text: str) -> None:
        """Say what happens next, until the next chunk or status (or the end). A text
        ``"PHASE - DETAIL"`` after ``PHASE`` (e.g. a refinement's step) updates the line in
        a terminal, and is printed at most every :data:`DETAIL_SECONDS` in a log."""
        if self.live:
            self.bar.stop()
            self.live = False
        if self.said == text and (self.spinner is not None or not self.status_console.is_terminal):
            return  # already shown
        phase = text.split(" - ", 1)[0]
        if phase != text and self.said.split(" - ", 1)[0] == phase:  # a detail of the phase
            if self.spinner is not None:
                self.spinner.update(status=f"{text} ...")
                self.said = text
                return
            if not self.status_console.is_terminal:
                if time.time() - self.detail_at >= DETAIL_SECONDS:
                    show_status(self.status_console, text)
                    self.detail_at = time.time()
                self.said = text
                return
        self._stop_spinner()
        self.spinner, self.said = show_status(self.status_console, text), text
        self.detail_at = time.time()

    def begin(self, text: str) -> None:
        """A spinner from the start (in a terminal only: a plain line comes with the first
        :meth:`status`, once the inputs were accepted, so that a refused fit stays one line)."""
        if self.status_console.is_terminal:
            self.status(text)

    def close(self) -> None:
        self._stop_spinner()
        if self.live:
            self.bar.stop()
            self.live = False

    def _stop_spinner(self) -> None:
        if self.spinner is not None:
            self.spinner.stop()
            self.spinner = None


def show_status(console: Console, text: str):
    """A spinner with ``text ...`` on ``console`` if it is a terminal (returned: ``.stop()``
    it), else the plain line ``text ...`` (returns None)."""
    if console.is_terminal:
        spinner = console.status(f"{text} ...")
        spinner.start()
        return spinner
    console.print(f"{text} ...", markup=False, highlight=False, soft_wrap=True)
    return None


@contextmanager
def status_line(console: Console, text: str):
    """:func:`show_status` for the duration of a block."""
    spinner = show_status(console, text)
    try:
        yield
    finally:
        if spinner is not None:
            spinner.stop()


@contextmanager
def fit_progress(
    total: int, console: Console, status_console: Console | None = None, on_update=None
):
    """A :class:`FitProgress` for the duration of a fit (its displays stopped at the end)."""
    shown = FitProgress(total, console, status_console or console, on_update)
    try:
        yield shown
    finally:
        shown.close()


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
