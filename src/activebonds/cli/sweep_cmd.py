"""``activebonds sweep``: many fits from a manifest, in parallel on Ray (docs/SWEEP.md)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer

from ..errors import InputError
from .app import app, fail, out


@app.command()
def sweep(
    manifest: Annotated[Path, typer.Argument(help="Sweep manifest (TOML; docs/SWEEP.md).")],
    out_dir: Annotated[
        Path, typer.Option("--out", help="Folder of the fits' run directories and the summary.")
    ] = ...,
    workers: Annotated[
        int | None,
        typer.Option(help="Fits run at once on a local Ray cluster (default: one per core)."),
    ] = None,
    address: Annotated[
        str | None,
        typer.Option(
            help="Join the Ray cluster at this address (e.g. ray://head:10001 or auto) "
            "instead of starting one; the files must be on a filesystem every node shares."
        ),
    ] = None,
    sequential: Annotated[
        bool, typer.Option(help="Run the fits one after another in this process (no Ray).")
    ] = False,
):
    """Run every fit of a manifest (each an ordinary run directory under --out), skipping
    finished runs and resuming interrupted ones; writes OUT/summary.csv and summary.html."""
    from .. import sweep as sw

    try:
        from ..sweep.run import use_ray as choose

        use_ray = choose(workers, address, sequential)
        jobs = sw.load_manifest(manifest)
        sw.check_out(jobs, out_dir)
        owned = sw.start_ray(workers or os.cpu_count(), address) if use_ray else False
    except InputError as e:
        fail(e)
    try:
        outcomes = _run(sw, jobs, out_dir, use_ray, sequential, address, workers)
    except KeyboardInterrupt:
        fail(
            "interrupted; the fits keep their checkpoints: run the same command again to continue",
            code=130,
        )
    finally:
        if owned:
            import ray

            ray.shutdown()
    csv_path, html_path = sw.write_summary(
        out_dir, jobs, outcomes, f"activebonds sweep: {manifest.name}"
    )
    _report(outcomes, csv_path, html_path)


def _run(sw, jobs, out_dir: Path, use_ray: bool, sequential: bool, address, workers):
    from .progress import sweep_progress

    n = len(jobs)
    if use_ray:
        from ..sweep.run import where

        out.print(
            f"{n} fit{'s' if n != 1 else ''} on {where(workers, address)}",
            markup=False,
            highlight=False,
        )
    elif not sequential:
        out.print(
            f"Ray is not installed: the {n} fits run one after another in this process "
            "(pip install 'activebonds[ray]' to run them in parallel)",
            markup=False,
            highlight=False,
        )
    out_dir.mkdir(exist_ok=True)
    with sweep_progress(n, out) as progress:
        if use_ray:
            return sw.run_ray(jobs, out_dir, progress)
        return sw.run_sequential(jobs, out_dir, progress)


def _report(outcomes, csv_path: Path, html_path: Path) -> None:
    counts = {a: sum(1 for o in outcomes if o.action == a) for a in ("ran", "resumed", "skipped")}
    bad = [o for o in outcomes if not o.ok]
    out.print(
        f"{len(outcomes)} fit{'s' if len(outcomes) != 1 else ''}: {counts['ran']} run, {counts['resumed']} resumed, "
        f"{counts['skipped']} skipped (finished before), {len(bad)} not completed",
        markup=False,
        highlight=False,
    )
    for o in bad:
        why = f": {o.message}" if o.message else ""
        out.print(f"  {o.name}: {o.status}{why}", markup=False, highlight=False)
    out.print(f"summary: {csv_path}, {html_path}", markup=False, highlight=False)
    if bad:
        raise typer.Exit(1)
