"""The ``report`` command: one self-contained HTML report of a run directory."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError


def report(
    run: Annotated[Path, typer.Argument(help="Run directory written by fit (or resume).")],
    out: Annotated[
        Path | None,
        typer.Option(
            "--out",
            help="HTML file to write (default RUN/report.html; its figures go beside it "
            "in STEM-figures/).",
        ),
    ] = None,
    frames: Annotated[
        int | None,
        typer.Option(
            "--n-frames",
            help="Frames of the original recording to predict from the fitted window's start "
            "(default: twice the window; beyond it tests generalisation).",
        ),
    ] = None,
):
    """Write an HTML report of a run: summary, convergence, parameters, neurons, animation."""
    from ..report import write_report
    from .app import err, fail
    from .progress import show_status

    shown = []
    try:
        path = write_report(
            run, out, frames=frames, status=lambda text: shown.append(show_status(err, text))
        )
    except InputError as e:
        fail(e)
    finally:
        for spinner in shown:
            if spinner is not None:
                spinner.stop()
    print(path)
