"""``activebonds fill``: fill a recording's marker gaps with a model's physics or a lab's
interpolation, and list every sample filled or left (:func:`activebonds.fill_file`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from ..identify.gaps.settings import MAX_STEPS
from .app import app, fail, say
from .arguments import check_order
from .shared_options import FittedModel


@app.command()
def fill(
    model: FittedModel,
    traj: Annotated[Path, typer.Argument(help="Recorded trajectory with gaps.")],
    out_path: Annotated[
        Path | None,
        typer.Option(
            "--out",
            help="File to write (.csv, .trc, .c3d, .npz, .mat), every marker and frame "
            "(default: the recording's name with _filled, in its own format).",
        ),
    ] = None,
    method: Annotated[
        str,
        typer.Option(
            help="model (the model's trajectory, fitted to the markers present around the "
            "gap), spline (cubic), linear, or pca (Gløersen & Federolf 2016)."
        ),
    ] = "model",
    markers: Annotated[
        str | None,
        typer.Option(
            help="Markers followed by the particles, in order: A,B,C (default: the model's). "
            "Only their gaps are filled."
        ),
    ] = None,
    frames: Annotated[
        str, typer.Option(help="Frame window START:STOP filled and fitted to.")
    ] = "0:",
    max_gap: Annotated[
        int | None,
        typer.Option(help="Leave gaps longer than this many frames (listed in the record)."),
    ] = None,
    denoise: Annotated[
        bool,
        typer.Option(
            help="With --method model: write the model's smoothed trajectory for every sample "
            "of the model's markers in the window, not only in the gaps."
        ),
    ] = False,
    context: Annotated[
        int,
        typer.Option(
            min=2, help="Frames on each side of a gap that the model's trajectory is fitted to."
        ),
    ] = 30,
    horizon: Annotated[
        int,
        typer.Option(
            min=1,
            help="Frames per shooting window of the model's fit (1: every frame's state free).",
        ),
    ] = 1,
    continuity: Annotated[
        float | None,
        typer.Option(
            help="Weight of the model's continuity defects against the position errors "
            "(default: from how much of the context's accelerations the model explains, "
            "0.3 for a model that explains none to 100 for one that explains them all).",
        ),
    ] = None,
    prior: Annotated[
        str | None,
        typer.Option(
            help="With --method model: pca fits the model's trajectory again with the PCA "
            "fill of the missing samples (its positions and its steps from frame to frame) as "
            "soft observations, weighed by the PCA fill's own error on artificial gaps against "
            "the model's residuals (default: none, the model alone). Helps on gaps of 30 "
            "frames and more, hurts on short ones (docs/experiments/gaps.md).",
        ),
    ] = None,
    max_steps: Annotated[
        int,
        typer.Option(
            min=1,
            help="Levenberg-Marquardt steps per fitted stretch, at most (a stretch that stops "
            "there is counted as not converged: raise it).",
        ),
    ] = MAX_STEPS,
    substeps: Annotated[
        int, typer.Option(min=1, help="Integration substeps per frame (as the model was fitted).")
    ] = 1,
    integrator: Annotated[
        str, typer.Option(help="euler or verlet (as the model was fitted).")
    ] = "euler",
    record: Annotated[
        Path | None,
        typer.Option(
            help="The sidecar CSV listing every sample of every gap: frame, marker, filled or "
            "left, method, estimated uncertainty (model: its standard error scaled by the "
            "residuals around the gap, see the gap-filling how-to; default: OUT's name with "
            ".gaps.csv)."
        ),
    ] = None,
    report: Annotated[
        Path | None,
        typer.Option(
            help="Also write this self-contained HTML page: per filled gap, the recording "
            "around it, the filled samples and the cubic spline's fill beside them."
        ),
    ] = None,
):
    """Fill the gaps of the model's markers: with the model's parameters fixed, its
    trajectory fitted (multiple shooting, the missing samples masked) to the markers present
    around each gap, or with a baseline. Gaps at the start or end of the window and gaps
    longer than --max-gap are left and listed."""
    from ..identify.gaps.files import fill_file
    from ..identify.gaps.settings import FillSettings
    from ..report.fill import check_page
    from .options import settings_of

    try:
        check_order("fill", model, [traj])
        settings = settings_of(
            FillSettings,
            method=method,
            denoise=denoise,
            prior=prior,
            continuity=continuity,
            integrator=integrator,
            markers=markers,
            frames=frames,
            max_gap=max_gap,
            context=context,
            horizon=horizon,
            max_steps=max_steps,
            substeps=substeps,
        )
        check_page(report)
        if out_path is None:  # the recording's own format, beside it
            out_path = traj.with_name(f"{traj.stem}_filled{traj.suffix}")
        filled = fill_file(model, traj, out_path, settings, record=record)
        if report is not None:
            from ..report.files import write_html
            from ..report.fill import fill_report

            page = fill_report(filled.plan, filled.values, method, traj.name, filled.note)
            write_html(report, page)
    except InputError as e:
        fail(e)
    for line in filled.lines():
        say(line)
    if report is not None:
        say(f"wrote {report} (the filled gaps drawn, the spline's fill beside)")
