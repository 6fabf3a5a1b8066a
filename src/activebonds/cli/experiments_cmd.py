"""``activebonds reproduce`` and ``activebonds demo``: the paper's experiments in one command."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from ..atomic import output_path
from ..errors import InputError
from .app import app, console, fail, out


def _parse_seeds(seeds: int) -> list[int]:
    if not 1 <= seeds <= 64:
        raise InputError("--seeds", f"must be between 1 and 64, got {seeds}")
    return list(range(seeds))


def _progress_runner(experiments: list[str], scale: str, seeds: list[int], folder: Path):
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from ..experiments.paper import run_experiment

    summaries = {}
    columns = (
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
    )
    with Progress(*columns, console=out) as bar:
        tasks: dict[str, int] = {}

        def progress(label: str, gen: int, total: int) -> None:
            if label not in tasks:
                tasks[label] = bar.add_task(label, total=total)
            bar.update(tasks[label], completed=gen, total=total)

        for name in experiments:
            summaries[name] = run_experiment(name, scale, seeds, folder / name, progress)
    return summaries


def _finish(summaries: dict, folder: Path, started: float) -> Path:
    from ..experiments.report import write_experiments_report
    from .progress import status_line

    with status_line(console(stderr=True), "writing the report"):  # figures: tens of seconds
        report = write_experiments_report(summaries, folder)
    for name, s in summaries.items():
        for config, c in s["configs"].items():
            st, ne = c["series"]["standard"], c["series"]["neural"]
            out.print(
                f"{name} {config}: fit RMS (median of {len(s['seeds'])} seeds) "
                f"standard {st['fit_rms_mm_median']:.3g} mm, neural {ne['fit_rms_mm_median']:.3g} mm; "
                f"next frames one-step {st['one_step_rms_mm_median']:.3g} vs {ne['one_step_rms_mm_median']:.3g} mm"
            )
        b = s.get("baselines")
        if b:
            floor = b["momentum_floor_mm"]
            out.print(
                f"{name} baselines: zero force {b['zero_force_fit_rms_mm']:.3g} mm (fit), "
                f"{b['zero_force_test_rms_mm']:.3g} mm (next frames); exact least squares "
                f"(standard) {b['lsq_standard_fit_rms_mm']:.5g} mm; momentum floor "
                + ("n/a" if floor is None else f"{floor:.4g} mm")
            )
    for line in verdict_lines(summaries):
        out.print(line, markup=False, highlight=False, emoji=False)
    out.print(f"done in {time.time() - started:.0f} s; report: {report}")
    return report


def verdict_lines(summaries: dict) -> list[str]:
    """Each series' verdicts (:mod:`activebonds.identify.judge.verdict`): on the fitted frames and
    the next ones, one step (medians over seeds) and K frames ahead, and per marker (the best
    seed's), beside zero force on the same frames."""
    from ..identify.judge.verdict import comparisons_from, verdict

    lines = []
    for name, s in summaries.items():
        b = s.get("baselines")
        if not b:
            continue
        a, z = b["test_frames"]
        for config, c in s["configs"].items():
            for series, r in c["series"].items():
                head = f"verdict, {name} {config} {series}"
                seeds = f" (median of {len(s['seeds'])} seeds)"
                fitted = verdict(r["fit_rms_mm_median"], b["zero_force_fit_rms_mm"])
                lines.append(f"{head}{seeds}, fitted frames, one step: {fitted.text()}")
                best = comparisons_from(r.get("held_out_best_seed"))
                medians = r.get("held_out_model_mm_median", [])
                for comp, median in zip(best, medians, strict=False):
                    v = verdict(median, comp.zero_force_mm)
                    lines.append(f"{head}{seeds}, frames {a}:{z}, {comp.what}: {v.text()}")
                    lines.append(
                        f"{head}, frames {a}:{z}, {comp.what}, per marker (best seed "
                        f"{r['best_seed']}): {comp.markers_text()}"
                    )
    return lines


@app.command()
def reproduce(
    experiment: Annotated[str, typer.Argument(help="synthetic (paper §4.1) or horse (§4.2).")],
    scale: Annotated[
        str, typer.Option(help="tiny, quick (minutes) or paper (the paper's sizes).")
    ] = "quick",
    seeds: Annotated[int, typer.Option(help="Seeds per configuration and series.")] = 5,
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("reproduce"),
):
    """Reproduce a paper experiment: standard vs neural bonds over several seeds, with figures,
    curves (CSV), generalisation to the following frames and an HTML report."""
    from ..experiments.paper import EXPERIMENTS

    started = time.time()
    try:
        if experiment not in EXPERIMENTS:
            raise InputError(
                "EXPERIMENT", f"expected one of {', '.join(EXPERIMENTS)}, got '{experiment}'"
            )
        if scale not in EXPERIMENTS[experiment].scales:
            raise InputError("--scale", f"expected tiny, quick or paper, got '{scale}'")
        out_dir = output_path(out_dir)
        summaries = _progress_runner([experiment], scale, _parse_seeds(seeds), out_dir)
        _finish(summaries, out_dir, started)
    except InputError as e:
        fail(e)


@app.command()
def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Output folder.")] = Path("demo"),
    seeds: Annotated[int, typer.Option(help="Seeds per series.")] = 3,
):
    """The main job on bundled data: quick versions of both paper experiments (synthetic
    trajectory and the real horse trot, standard vs neural bonds), then the report."""
    started = time.time()
    try:
        out_dir = output_path(out_dir)
        summaries = _progress_runner(["synthetic", "horse"], "quick", _parse_seeds(seeds), out_dir)
        _finish(summaries, out_dir, started)
    except InputError as e:
        fail(e)
