"""The ``activebonds`` command line (DESIGN.md §4).

Bad input (model file, trajectory, option, run directory) prints one line naming the file and
field and exits with code 2; nothing is half-written. An interrupted fit exits with 130 after
saving a checkpoint (cli/interrupts.py); a write that fails mid-run (a full disk) exits with 1,
its newest checkpoint kept (cli/preflight.py).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated

from . import interrupts

interrupts.install()  # the command line's own process only, before the slow imports

import typer  # noqa: E402
from rich.table import Table  # noqa: E402

from ..errors import InputError  # noqa: E402
from ..identify.settings import (  # noqa: E402
    AUTO,
    FitSettings,
    frames_text,
    parse_frames,
    parse_markers,
)
from .app import app, fail, out, parse_option_frames, say  # noqa: E402
from .arguments import check_order  # noqa: E402
from .progress_bar import run_progress as _progress  # noqa: E402
from .shared_options import (  # noqa: E402
    AsJson,
    Bonds,
    Frames,
    Generations,
    Integrator,
    ModelFile,
    ModelMarkers,
    Population,
    Seed,
    Strict,
    Substeps,
)


@app.command()
def info(
    traj: Annotated[Path, typer.Argument(help="Trajectory file (.csv, .trc, .c3d, .mat, .npz).")],
    as_json: AsJson = False,
    strict: Strict = False,
    markers: Annotated[
        str | None,
        typer.Option(
            help="A,B,C: the frame windows where all of these markers are present (for "
            "fit --frames)."
        ),
    ] = None,
):
    """Markers, frames, rate, units, gaps and coverage of a trajectory file, and its vertical
    axis guessed twice (lowest markers; acceleration in flight)."""
    from ..data import describe, read_trajectory

    chosen = list(parse_markers(markers) or ()) or None
    try:
        d = describe(read_trajectory(traj, strict=strict), chosen)
    except InputError as e:
        fail(e)
    if as_json:
        print(json.dumps(d, indent=2))
        return
    table = Table(title=str(traj), show_header=False)
    for key in ("frames", "rate", "dt", "duration", "units", "dimension", "total_gaps"):
        value = d[key]
        if key == "rate":
            value = f"{value:g} Hz"
        elif key in ("dt", "duration"):
            value = f"{value:.6g} s"
        elif key == "units":
            value = f"{value} in the file (converted to metres)"
        table.add_row(LABELS.get(key, key), str(value))
    table.add_row("markers", f"{len(d['markers'])}: " + ", ".join(d["markers"]))
    gaps = {k: v for k, v in d["gaps"].items() if v}
    if gaps:
        table.add_row("missing samples", ", ".join(f"{k} {v}" for k, v in gaps.items()))
    if d["ground"] is not None:
        table.add_row("vertical, ground (guessed)", d["ground"]["text"])
    else:
        table.add_row("vertical, ground (guessed)", "none (fewer than two markers or frames)")
    table.add_row("vertical from gravity (guessed)", d["gravity"]["text"])
    agree = {True: "agree", False: "disagree", None: "not comparable (one guess only)"}
    table.add_row("the two vertical guesses", agree[d["vertical_agree"]])
    cov = d["coverage"]
    table.add_row("all markers present", _windows_text(cov["all"]))
    if cov["chosen"] is not None:
        table.add_row(f"{','.join(cov['chosen']['markers'])} present", _windows_text(cov["chosen"]))
    out.print(table)
    per_marker = Table(title="coverage", show_header=True)
    for column in ("marker", "present", "missing frames", "gaps", "longest gap-free window"):
        per_marker.add_column(column)
    for name, c in cov["markers"].items():
        window = c["longest"]
        per_marker.add_row(
            name,
            f"{100 * c['present']:.1f} %",
            str(c["missing_frames"]),
            str(c["gaps"]),
            "none" if window is None else f"{window['frames']} ({window['length']} frames)",
        )
    out.print(per_marker)


# info's rows, as people read them ("total_gaps" counts missing marker-frames, not gaps)
LABELS = {"total_gaps": "missing samples"}


def _windows_text(record: dict) -> str:
    """'in 93.2 % of the frames; longest: 120:480 (360 frames), 0:100 (100 frames)'."""
    windows = record["windows"]
    if not windows:
        return "in no frame"
    listed = ", ".join(f"{w['frames']} ({w['length']} frames)" for w in windows)
    return f"in {100 * record['present']:.1f} % of the frames; longest: {listed}"


@app.command()
def simulate(
    model: ModelFile,
    frames: Annotated[
        int, typer.Option("--n-frames", help="Number of frames to write.", min=2)
    ] = ...,
    rate: Annotated[float, typer.Option(help="Frame rate in Hz.")] = ...,
    out_path: Annotated[Path, typer.Option("--out", help="Trajectory to write.")] = ...,
    start: Annotated[
        Path | None,
        typer.Option("--from", help="Start from the first two frames of this recording."),
    ] = None,
    substeps: Substeps = 1,
    integrator: Integrator = "euler",
):
    """Free-run a model from its particles' initial state (or a recording's first two frames)."""
    from ..simulation import simulate_to_file

    try:
        check_order("simulate", model)
        n = simulate_to_file(model, frames, rate, out_path, start, substeps, integrator)
    except InputError as e:
        fail(e)
    except ArithmeticError as e:
        fail(str(e), code=1)
    out.print(f"wrote {n} frames to {out_path}")


# the fit's defaults are the settings' own (one source for Python and the command line)
DEFAULT = {name: f.default for name, f in FitSettings.model_fields.items()}


@app.command()
def fit(
    model: ModelFile,
    traj: Annotated[
        list[Path],
        typer.Argument(
            help="Recorded trajectory; several (trials of one subject, one frame rate) are "
            "fitted at once, their costs added."
        ),
    ],
    out_dir: Annotated[Path, typer.Option("--out", help="Run directory to create.")] = ...,
    markers: ModelMarkers = None,
    frames: Frames = frames_text(DEFAULT["frames"]),
    bonds: Bonds = DEFAULT["bonds"],
    population: Population = DEFAULT["population"],
    generations: Generations = DEFAULT["generations"],
    seed: Seed = DEFAULT["seed"],
    horizon: Annotated[
        str | None,
        typer.Option(
            help="Frames predicted from each start: the ES's cost uses the first (1 with "
            "--cost shooting); with --refine lm, one refinement stage per entry, each from "
            "the previous one's result (a curriculum, e.g. 1,5,20). As long as the window: "
            "a free run. Default: 1 (10 with --cost auto choosing shooting)."
        ),
    ] = None,
    refine: Annotated[
        str,
        typer.Option(
            help="lm (the default): Levenberg-Marquardt (optimistix) polishes the ES's best "
            "on the residuals of --cost, one stage per --horizon entry; none: the ES only."
        ),
    ] = DEFAULT["refine"],
    max_steps: Annotated[
        int,
        typer.Option(
            min=1,
            help="Levenberg-Marquardt steps per refinement stage, at most (a stage that "
            "stops there says so: raise it).",
        ),
    ] = DEFAULT["max_steps"],
    cost: Annotated[
        str,
        typer.Option(
            help="The refinement's cost: restart (from the recorded states every horizon "
            "frames; 1: the paper's one-step cost), shooting (multiple shooting: windows "
            "of horizon frames whose start states are fitted too; unbiased by noise) or "
            "auto: shooting (10-frame windows unless --horizon) where a window has at most "
            "300 unknowns, else restart."
        ),
    ] = AUTO,
    smooth: Annotated[
        int,
        typer.Option(
            help="Savitzky-Golay window (odd number of frames >= 5) applied to the restart "
            "states of the cost (not to the targets); 0: off. Reduces the noise bias."
        ),
    ] = DEFAULT["smooth"],
    substeps: Annotated[int, typer.Option(help="Integration steps per frame.")] = DEFAULT[
        "substeps"
    ],
    integrator: Integrator = DEFAULT["integrator"],
    checkpoint_every: Annotated[
        int, typer.Option(help="Generations between checkpoints.")
    ] = DEFAULT["checkpoint_every"],
    precision: Annotated[
        str,
        typer.Option(
            help="float64, float32, or mixed (the ES's one-step cost in float32, the rest in "
            "float64: faster, see benchmarks/README.md)."
        ),
    ] = DEFAULT["precision"],
    adapt_variants: Annotated[
        bool, typer.Option(help="Adapt the mutation-variant rates to their success.")
    ] = DEFAULT["adapt_variants"],
    init: Annotated[
        str,
        typer.Option(
            help="uniform (within the bounds), lsq (one individual at the exact "
            "least-squares optimum of the linear parameters, neural gains 0) or model (one "
            "individual at the model file's values, e.g. a structure result's)."
        ),
    ] = DEFAULT["init"],
    optimizer: Annotated[
        str,
        typer.Option(
            help="es (the paper's evolution strategy), random (pure random search, a "
            "baseline) or cmaes (CMA-ES, evosax)."
        ),
    ] = DEFAULT["optimizer"],
    overwrite: Annotated[bool, typer.Option(help="Replace an existing run directory.")] = False,
    validate: Annotated[
        str | None,
        typer.Option(
            help="Frames START:STOP of the recording the fit does not use: measure the "
            "one-step RMS, free-run RMS and frames within 50 mm there (RUN/validation.json)."
        ),
    ] = None,
    strict: Strict = False,
):
    """Identify the model's free parameters from a recorded trajectory; writes RUN/."""
    from ..identify import fit as run_fit
    from ..identify.driver import compiling_text
    from ..identify.prepare import prepare
    from ..identify.rundir import RunWriteError
    from .preflight import check_output_folder, write_failure_line

    interrupts.expect_run(out_dir)
    try:
        check_order("fit", model, traj)
        check_cost(cost)
        settings = _fit_settings(locals())
        check_output_folder(out_dir, overwrite)  # before any computation
        prepared = prepare(
            model,
            traj if len(traj) > 1 else traj[0],
            settings,
            horizon_given=horizon is not None,
            strict=strict,
        )
        if prepared.cost_note:
            say(prepared.cost_note)
        out.print(prepared.predictions, markup=False, highlight=False)
        with _progress(generations, compiling_text(optimizer)) as progress:
            result = run_fit(
                prepared,
                None,
                out=out_dir,
                overwrite=overwrite,
                progress=progress,
                status=progress.status,
            )
        interrupts.fit_returned(result.status)
    except InputError as e:
        fail(e)
    except RunWriteError as e:
        fail(write_failure_line(out_dir, e), code=1)
    except KeyboardInterrupt:
        interrupts.stop(_interrupted_fit(out_dir))
    _summary(result)


def _fit_settings(options: dict) -> FitSettings:
    """The fit's settings from its command's options (named as the settings' fields, but for
    the texts parsed here), or a one-line error naming the option."""
    from .options import settings_from_options

    parsed = ("markers", "frames", "horizon")
    given = {k: v for k, v in options.items() if k in FitSettings.model_fields and k not in parsed}
    horizon, validate = options["horizon"], options["validate"]
    return settings_from_options(
        **given,
        markers=parse_markers(options["markers"]),
        frames=parse_option_frames(options["frames"], parse_frames),
        horizon=parse_horizons(horizon or ",".join(map(str, DEFAULT["horizon"]))),
        validation=parse_option_frames(validate, parse_frames, "--validate") if validate else None,
    )


def check_cost(cost: str) -> None:
    """``--cost``: auto or a registered cost's name, or a one-line error listing them."""
    from ..identify.costs import names

    accepted = (AUTO, *names())
    if cost not in accepted:
        raise InputError(
            "--cost", f"expected {', '.join(accepted[:-1])} or {accepted[-1]}, got '{cost}'"
        )


def _interrupted_fit(out_dir: Path) -> str:
    """The true message of a fit interrupted (in-process: the command line's own process acts
    on interrupts only once its run exists, cli/interrupts.py)."""
    from ..identify.rundir import RunDir

    if interrupts.active() or RunDir(out_dir).is_run():
        return interrupts.resume_advice(out_dir)
    return "interrupted before the run started; nothing was written"


@app.command()
def resume(
    run: Annotated[Path, typer.Argument(help="Run directory of an interrupted fit.")],
    generations: Annotated[
        int | None, typer.Option(help="New total number of generations (to extend a run).")
    ] = None,
    force: Annotated[
        bool, typer.Option(help="Continue even if inputs, settings or versions changed.")
    ] = False,
):
    """Continue an interrupted fit exactly where its last checkpoint stopped."""
    from ..identify import resume as run_resume
    from ..identify.rundir import RunDir, RunWriteError
    from .preflight import write_failure_line

    try:
        total = generations or RunDir(run).meta()["settings"]["generations"]
        interrupts.resuming(run)
        with _progress(total, "loading the run and compiling") as progress:
            result = run_resume(
                run, force=force, generations=generations, progress=progress, status=progress.status
            )
        interrupts.fit_returned(result.status)
    except InputError as e:
        fail(e)
    except RunWriteError as e:
        fail(write_failure_line(run, e), code=1)
    except KeyboardInterrupt:
        interrupts.stop(interrupts.resume_advice(run))
    _summary(result)


def parse_horizons(text: str) -> tuple[int, ...]:
    """'1,5,20' -> (1, 5, 20), or a one-line error."""
    try:
        return tuple(int(h) for h in text.split(","))
    except ValueError:
        raise InputError(
            "--horizon", f"expected integers separated by commas, got '{text}'"
        ) from None


def _summary(result) -> None:
    """The fit's outcome, then what each post-fit stage says of it (identify.stages)."""
    if result.status != "completed":
        fail(f"{result.run or 'fit'}: {result.status}", code=1)
    undecided = sum(1 for b in result.model.spec.bond if b.optional and b.present is None)
    if undecided:
        say(
            f"note: {undecided} optional bond(s) without a decision were fitted as present; "
            "'activebonds structure' decides which the data need"
        )
    say(
        f"{result.status}: best RMS error {result.rms_mm:.4g} mm "
        f"({', '.join(f'{k} {v:.3g}' for k, v in result.local_rms_mm.items())})"
    )
    n_recordings = len(result.identification.all_data)
    if n_recordings > 1:
        say(
            f"fitted on {n_recordings} recordings at once; the free runs below are of the "
            f"first ({result.identification.data.source})"
        )
    for line in result.lines():
        say(line)
    from ..model.names import bounds_line, parameter_rows

    searched = result.identification.model  # its bounds were searched; the genome is its
    rows = parameter_rows(searched, searched.layout.natural(result.genome))
    if (line := bounds_line(rows)) is not None:
        say(line)
    if result.run is not None:
        from ..identify.rundir import RunDir

        best = RunDir(result.run).best_model_path
        say(f"run directory: {result.run}  (best model: {best})")


def main() -> None:
    """Entry point: usage errors become one line and exit code 2."""
    from ..runtime import compilation_cache, fast_cpu_flags
    from .app import command_line, one_line_warnings

    one_line_warnings()  # a reader's warning about a file: "warning: FILE: line N: ..."
    fast_cpu_flags()
    try:  # the compilation cache (it imports JAX) once a command runs, not for help or errors
        code = command_line(compilation_cache)(standalone_mode=False)
    except typer.Exit as e:
        code = e.exit_code
    except typer.Abort:
        print("error: aborted", file=sys.stderr)
        code = 130
    except Exception as e:  # usage errors of the command-line parser
        if not (hasattr(e, "format_message") and hasattr(e, "exit_code")):
            raise
        ctx = getattr(e, "ctx", None)
        cmd = ctx.command_path if ctx is not None else "activebonds"
        message = " ".join(e.format_message().split())
        if message:
            print(f"error: {cmd}: {message}", file=sys.stderr)
        code = 2 if e.exit_code == 1 else e.exit_code
    sys.exit(code if isinstance(code, int) else 0)


# The other commands, after these in --help; their modules register them on the app.
from . import experiments_cmd  # noqa: E402,F401
from .report_cmd import report  # noqa: E402

app.command(name="report")(report)

from . import (  # noqa: E402,F401
    auto_cmd,
    baselines_cmd,
    datasets_cmd,
    evaluate_cmd,
    export_cmd,
    fill_cmd,
    scaffold_cmd,
    structure_cmd,
    sweep_cmd,
)
