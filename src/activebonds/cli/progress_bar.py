"""The fit's progress bar as the commands open it (``fit``, ``resume``, ``auto``): light to
import, so ``--help`` stays fast (the bar itself, :mod:`.progress`, is imported on use)."""

from __future__ import annotations

from contextlib import contextmanager

from . import interrupts
from .app import console, out


@contextmanager
def run_progress(total: int, starting: str):
    """The fit's progress bar and status lines (cli/progress.py); each finished chunk is a
    point where an interrupt is acted on."""
    from .progress import fit_progress

    status_console = console(stderr=True)
    with fit_progress(total, out, status_console, on_update=interrupts.check) as progress:
        progress.begin(starting)
        yield progress
