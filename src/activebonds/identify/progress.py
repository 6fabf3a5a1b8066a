"""``fit(..., progress=True)``: a progress bar in a notebook or a terminal.

In Jupyter, an HTML ``<progress>`` element updated in place (IPython's ``display`` with a
display id: no widget library needed); elsewhere, rich's progress bar on standard error (in a
terminal it redraws; in a log, the final bar is printed when the fit ends). It shows the
generation, the best RMS error and the elapsed time, and before the silent phases
(compilation, refinement, baselines, uncertainty) what the fit is doing. A function given as
``progress`` is called instead, ``progress(generation, total, best_rms_mm)`` after each chunk.
"""

from __future__ import annotations

import html
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Column


class ProgressBar:
    """The callback ``fit(progress=True)`` passes on: call it with (generation, total, best
    RMS mm); :meth:`status` says what happens next; :meth:`close` ends the display."""

    def __init__(self, console: Console | None = None):
        self.console = console or Console(stderr=True)
        self.jupyter = self.console.is_jupyter
        self.generation, self.total, self.rms = 0, 0, float("nan")
        self.doing = "starting"
        self.started = time.time()
        self.handle = None  # Jupyter: the display being updated
        self.bar: Progress | None = None  # elsewhere: rich's bar
        self.task = None

    def __call__(self, generation: int, total: int, rms: float) -> None:
        self.generation, self.total, self.rms = int(generation), int(total), float(rms)
        self.doing = "evolving"
        self._show()

    def status(self, text: str) -> None:
        self.doing = text
        self._show()

    def close(self) -> None:
        if self.bar is not None:
            self.doing = "done"
            self._show()
            self.bar.stop()
            self.bar = None
        elif self.handle is not None:
            self.doing = "done"
            self._show()

    def text(self) -> str:
        """``generation 20/50, best 4.21 mm, 3.2 s: evolving``."""
        rms = f"{self.rms:.4g}" if self.rms == self.rms else "-"
        elapsed = time.time() - self.started
        return (
            f"generation {self.generation}/{self.total or '?'}, best {rms} mm, "
            f"{elapsed:.1f} s: {self.doing}"
        )

    def _show(self) -> None:
        if self.jupyter:
            self._show_html()
        else:
            self._show_rich()

    def _show_html(self) -> None:
        from IPython.display import HTML, display

        total = max(self.total, 1)
        page = HTML(
            f'<div><progress value="{self.generation}" max="{total}" style="width:30ex">'
            f"</progress> {html.escape(self.text())}</div>"
        )
        if self.handle is None:
            self.handle = display(page, display_id=True)
        else:
            self.handle.update(page)

    def _show_rich(self) -> None:
        rms = f"{self.rms:.4g}" if self.rms == self.rms else "-"
        if self.bar is None:
            fixed = Column(no_wrap=True)
            self.bar = Progress(
                TextColumn("generation", table_column=fixed),
                MofNCompleteColumn(table_column=Column(no_wrap=True)),
                BarColumn(bar_width=20),
                TextColumn("best {task.fields[rms]} mm", table_column=Column(no_wrap=True)),
                TimeElapsedColumn(table_column=Column(no_wrap=True)),
                TextColumn("{task.fields[doing]}", markup=False),
                console=self.console,
                transient=False,
            )
            self.task = self.bar.add_task("fit", total=self.total or None, rms=rms, doing="")
            self.bar.start()
        self.bar.update(
            self.task,
            completed=self.generation,
            total=self.total or None,
            rms=rms,
            doing=short(self.doing),
        )


def short(text: str, limit: int = 40) -> str:
    """A status line for the bar's last column: up to its first parenthesis, at most
    ``limit`` characters."""
    text = text.split(" (")[0]
    return text if len(text) <= limit else text[: limit - 1] + "…"


@contextmanager
def shown(
    progress: Callable | bool | None, status: Callable | None
) -> Iterator[tuple[Callable | None, Callable | None]]:
    """The ``progress`` and ``status`` callbacks a fit uses: ``progress=True`` a
    :class:`ProgressBar` (its :meth:`~ProgressBar.status` too unless ``status`` is given),
    closed at the end; a function as it is; False or None: nothing shown."""
    if progress is not True:
        yield (progress or None), status
        return
    bar = ProgressBar()
    try:
        yield bar, (status if status is not None else bar.status)
    finally:
        bar.close()
