"""``activebonds auto``: from a recording to an evaluated model in one command
(the auto package: scaffold, structure, fit, evaluate on a held-out tail, report)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from .app import app, fail, out, parse_option_frames
from .shared_options import (
    AllMarkers,
    Frames,
    Generations,
    Gravity,
    Population,
    Seed,
    TotalMass,
    Up,
)


@app.command()
def auto(
    traj: Annotated[
        list[str],
        typer.Argument(
            help="Recorded trajectory; several (files, folders of recordings, globs): a "
            "dataset, each trial in OUT/<its name>, OUT/summary.csv and OUT/index.html.",
        ),
    ],
    out_dir: Annotated[
        Path,
        typer.Option(
            "--out",
            help="Output folder: scaffold.toml, structure.toml/.json, run/, "
            "evaluation.json, report.html, auto.json.",
        ),
    ] = ...,
    markers: AllMarkers = None,
    frames: Frames = "0:",
    held_out: Annotated[
        float,
        typer.Option(help="Share of the window's frames held out at its end, never fitted."),
    ] = 0.2,
    total_mass: TotalMass = None,
    up: Up = None,
    gravity: Gravity = None,
    population: Population = 40,
    generations: Generations = 200,
    seed: Seed = 0,
    ahead: Annotated[
        int, typer.Option(help="Frames ahead of the multi-step verdict (evaluate --horizon).")
    ] = 10,
    overwrite: Annotated[
        bool, typer.Option(help="Replace an earlier output folder of activebonds auto.")
    ] = False,
    verbose: Annotated[
        bool, typer.Option("--verbose", help="Say each fit's summary, not one line a fit.")
    ] = False,
    workers: Annotated[
        int | None,
        typer.Option(help="A dataset's trials at once on this machine (default: its CPUs)."),
    ] = None,
    address: Annotated[
        str | None,
        typer.Option(help="A dataset's trials on the Ray cluster at this address (or auto)."),
    ] = None,
    sequential: Annotated[
        bool, typer.Option("--sequential", help="A dataset's trials one after another, no Ray.")
    ] = False,
    subject: Annotated[
        bool,
        typer.Option(
            "--subject",
            help="The trials are one subject's: each left out in turn, a model fitted on the "
            "others judged on it (OUT/subject.csv).",
        ),
    ] = False,
):
    """From a recording to an evaluated model: scaffold a candidate model of the fitted frames,
    decide its springs (structure), fit it (the cost as fit --cost auto), evaluate it on the
    held-out tail and the fitted frames beside zero force, write the report; the verdict last.
    Run again with the same recording and options, the finished steps are kept and an
    interrupted fit resumes. Several recordings: each trial so, in parallel on Ray."""
    from .. import auto as auto_package
    from ..identify.rundir import RunWriteError
    from ..identify.settings import parse_frames, parse_markers
    from .app import say
    from .preflight import write_failure_line
    from .progress_bar import run_progress as _progress

    try:
        options = auto_package.Options(
            markers=parse_markers(markers),
            frames=parse_option_frames(frames, parse_frames),
            held_out=held_out,
            total_mass=total_mass,
            up=up,
            gravity=gravity,
            population=population,
            generations=generations,
            seed=seed,
            ahead=ahead,
        )
        if subject or len(traj) > 1 or Path(traj[0]).is_dir() or any(c in traj[0] for c in "*?["):
            from .auto_dataset import run_dataset_command

            run_dataset_command(traj, out_dir, options, workers, address, sequential, subject)
            return
        outcome = auto_package.run(
            Path(traj[0]),
            out_dir,
            options,
            overwrite=overwrite,
            say=say,
            fit_progress=_progress,
            verbose=verbose,
        )
    except InputError as e:
        fail(e)
    except RunWriteError as e:
        fail(write_failure_line(out_dir / "run", e), code=1)
    except RuntimeError as e:
        fail(str(e), code=1)
    except KeyboardInterrupt:
        fail(
            f"interrupted; the finished steps are kept in {out_dir}: run the same command "
            "again to continue (an interrupted fit resumes from its checkpoint)",
            code=130,
        )
    for line in outcome.verdict_lines():
        say(line)
    out.print(f"output: {out_dir} (report: {outcome.folder.report})", markup=False)
    say(outcome.verdict())
