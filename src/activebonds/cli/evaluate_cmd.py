"""``activebonds evaluate``: score any model on any recording, beside the zero-force baseline."""

from __future__ import annotations

import json
from typing import Annotated

import typer
from rich.table import Table
from rich.text import Text

from ..errors import InputError
from .app import app, fail, out, parse_option_frames
from .arguments import check_order
from .shared_options import AsJson, FittedModel, Frames, ModelMarkers, Recording


@app.command()
def evaluate(
    model: FittedModel,
    traj: Recording,
    markers: ModelMarkers = None,
    frames: Frames = "0:",
    substeps: Annotated[
        int | None,
        typer.Option(
            help="Integration substeps per frame, as the model was fitted (default: the run's "
            "for a RUN/best_model.toml, else 1)."
        ),
    ] = None,
    integrator: Annotated[
        str | None,
        typer.Option(
            help="euler or verlet, as the model was fitted (default: the run's for a "
            "RUN/best_model.toml, else euler)."
        ),
    ] = None,
    horizon: Annotated[
        int,
        typer.Option(
            help="Frames ahead of the multi-step comparison: the RMS error of the model's "
            "free run HORIZON frames from each recorded state, beside zero force's (1: one "
            "step only)."
        ),
    ] = 10,
    gait: Annotated[
        bool,
        typer.Option(
            "--gait",
            help="Also score free runs as a gait, whatever their phase: 10 runs of 5 strides "
            "from frames spread over the window; the feet's period and excursions, the body's "
            "largest distance from its mean position and the cycle-average RMS against the "
            "recording's mean gait, each beside zero force's and its target.",
        ),
    ] = False,
    feet: Annotated[
        str | None,
        typer.Option(
            help="With --gait: the feet, particle names separated by commas (default: the "
            "particles of the model's contacts, else the lowest markers)."
        ),
    ] = None,
    up: Annotated[
        str | None,
        typer.Option(
            help="With --gait: the vertical axis, e.g. +Z or -Y, or a direction as three "
            "numbers (default: against the model's gravity, else guessed from the recording)."
        ),
    ] = None,
    body: Annotated[
        str | None,
        typer.Option(
            help="Also count the free runs' frames within 50 mm (and their RMS) over these "
            "particles alone, e.g. Head,Withers,Sacrum: a run holding the body while a foot "
            "swings off counts on."
        ),
    ] = None,
    origin: Annotated[
        int | None,
        typer.Option(
            help="The recording's frame where the model's time is 0, e.g. 0 for a model fitted "
            "on 0:300 and judged on 300:600: a rhythmic drive's clock and a moving anchor start "
            "there, an entrained drive's phase runs on from there as in fit --validate "
            "(default: the window's first frame)."
        ),
    ] = None,
    burn_in: Annotated[
        int | None,
        typer.Option(
            min=1,
            help="Also judge free runs as system identification does: the state estimated "
            "from the N recorded frames before each start (parameters held), then the run; "
            "the RMS error 1-100 frames on and the frames within 50 mm, beside zero force "
            "(the least-squares line through the same frames).",
        ),
    ] = None,
    as_json: AsJson = False,
):
    """Score a model on a recording, fitting nothing: one-step RMS, free-run RMS and frames a
    free run stays within 50 mm (as fit's summary and --validate), the RMS error HORIZON
    frames ahead, for the model and the zero-force (constant-velocity) predictor, overall and
    per particle (mm), each with its verdict (better than zero force by X %, or worse)."""
    from ..identify.settings import parse_frames, parse_markers
    from ..report.evaluate_inputs import evaluate_from_options, run_integration

    try:
        check_order("evaluate", model, [traj])
        substeps, integrator = run_integration(model, substeps, integrator)
        found = evaluate_from_options(
            model,
            traj,
            frames=parse_option_frames(frames, parse_frames),
            markers=parse_markers(markers),
            substeps=substeps,
            integrator=integrator,
            horizon=horizon,
            gait=gait,
            feet=feet,
            up=up,
            body=body,
            origin=origin,
            burn_in=burn_in,
        )
    except InputError as e:
        fail(e)
    if as_json:
        print(json.dumps({"model_file": str(model), **found.record()}, indent=2))
        return
    out.print(_overall_table(found, f"{model} on {traj}"))
    out.print(_particle_table(found))
    for line in found.lines():
        out.print(line, markup=False, highlight=False, emoji=False)
    if found.gait is not None:
        _print_gait(found.gait)


def _overall_table(found, title: str) -> Table:
    """The model's and zero force's numbers over every particle (and over --body's)."""
    m, z = found.model, found.zero_force
    a, b = found.frames
    how = f"{found.substeps} {found.integrator} substep{'s' * (found.substeps > 1)} per frame"
    table = Table(title=f"{title}, frames {a}:{b} ({how})")
    table.add_column("")
    table.add_column("model", justify="right")
    table.add_column("zero force", justify="right")
    table.add_column("verdict")
    one = found.comparisons[0]
    table.add_row(
        "one-step RMS (mm)", _mm(m.one_step_rms_mm), _mm(z.one_step_rms_mm), _word(one.overall)
    )
    for c in found.comparisons[1:]:
        table.add_row(
            f"{c.horizon}-frame-ahead RMS (mm)",
            _mm(c.model_mm),
            _mm(c.zero_force_mm),
            _word(c.overall),
        )
    table.add_row("free-run RMS (mm)", _mm(m.free_run_rms_mm), _mm(z.free_run_rms_mm), "")
    table.add_row(
        f"frames within {m.threshold_mm:g} mm (median of {len(m.starts)} starts)",
        m.frames_text(),
        z.frames_text(),
        "",
    )
    if found.body is not None:
        bm, bz = found.body["model"], found.body["zero_force"]
        which = ", ".join(found.body_markers)
        table.add_row(
            f"free-run RMS, {which} (mm)", _mm(bm.free_run_rms_mm), _mm(bz.free_run_rms_mm), ""
        )
        table.add_row(
            f"frames within {bm.threshold_mm:g} mm, {which} (median of {len(bm.starts)} starts)",
            bm.frames_text(),
            bz.frames_text(),
            "",
        )
    return table


def _particle_table(found) -> Table:
    """Each particle's RMS errors, the model's beside zero force's, red where not better."""
    per = Table(title="per particle (RMS error, mm; red: not better than zero force)")
    for col in ("particle", "marker"):
        per.add_column(col)
    heads = ["one-step", "one-step zero force"]
    for c in found.comparisons[1:]:
        heads += [f"{c.horizon} ahead", f"{c.horizon} ahead zero force"]
    heads += ["free run", "free run zero force"]
    for col in heads:
        per.add_column(col, justify="right")
    verdicts = [list(c.per_marker.values()) for c in found.comparisons]
    for i, p in enumerate(found.particles):
        cells = [p.particle, p.marker]
        for c, v in zip(found.comparisons, verdicts, strict=True):
            cells += [_judged(c.model_per_marker[i], v[i]), _mm(c.zero_force_per_marker[i])]
        cells += [_mm(p.free_run_rms_mm), _mm(p.zero_force_free_run_rms_mm)]
        per.add_row(*cells)
    return per


def _print_gait(found) -> None:
    from ..report.gait_runs import COLUMNS

    table = Table(title="gait (free runs, whatever their phase)", caption=found.caption)
    for i, col in enumerate(COLUMNS):
        table.add_column(col, justify="left" if i in (0, 7) else "right")
    for row in found.rows():
        table.add_row(*(Text(c, style="bold red") if c == "FAIL" else c for c in row))
    out.print(table)


def _mm(x: float) -> str:
    return "—" if x != x else f"{x:.6g}"


def _word(v) -> Text:
    return Text(v.word, style="" if v.better or v.better is None else "bold red")


def _judged(x: float, v) -> Text:
    """A model's number, red where it is not better than zero force."""
    return Text(_mm(x), style="bold red" if v.better is False else "")
