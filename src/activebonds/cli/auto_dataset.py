"""``activebonds auto`` over several recordings (:mod:`activebonds.auto.dataset`): where the
trials run (Ray on this machine or a cluster, or one after another), a line a finished
trial, the summary's path last."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import InputError
from .app import out, say


def run_dataset_command(recordings, out_dir: Path, options, workers, address, sequential,
                        subject=False):  # fmt: skip
    from ..auto import dataset
    from ..sweep import run as sweep_run

    use_ray = sweep_run.use_ray(workers, address, sequential)
    items = dataset.trials(recordings)
    if subject and len(items) < 3:
        raise InputError("--subject", f"needs 3 trials or more, got {len(items)}")
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(out_dir, "exists and is not a folder; choose another --out")
    owned = sweep_run.start_ray(workers or os.cpu_count(), address) if use_ray else False
    if use_ray:
        say(
            f"{len(items)} trial(s) on {sweep_run.where(workers, address)}; each in {out_dir}/<trial>"
        )
    else:
        why = "" if sequential else " (pip install 'activebonds[ray]' to run them in parallel)"
        say(f"{len(items)} trial(s), one after another{why}; each in {out_dir}/<trial>")

    def done(row: dict) -> None:
        if row["status"] == "done":
            say(
                f"{row['trial']}: {row['family'] or '-'}, held out one step {row['one_step_mm']}"
                f" mm (zero force {row['zero_force_one_step_mm']} mm, {row['one_step_verdict']}),"
                f" {row['markers_worse_one_step']} of {row['markers']} markers worse"
            )
        else:
            say(f"{row['trial']}: {row['status']}: {row['message']}")

    try:
        rows = dataset.run_dataset(items, out_dir, options, use_ray, done)
    finally:
        if owned:
            import ray

            ray.shutdown()
    better = sum(1 for r in rows if r["one_step_verdict"] == "better")
    failed = sum(1 for r in rows if r["status"] != "done")
    if subject:
        from ..auto.subject import leave_one_out

        left = leave_one_out(items, out_dir, options, {r["trial"]: r for r in rows}, say)
        won = sum(1 for r in left if r["subject_one_step_verdict"] == "better")
        say(
            f"subject: the model of the other trials predicts the left-out trial one step "
            f"better than zero force in {won} of {len(left)}: {out_dir}/subject.csv"
        )
    out.print(f"output: {out_dir}/summary.csv, {out_dir}/index.html", markup=False)
    say(
        f"verdict: held out one step better than zero force in {better} of {len(rows)} trials"
        + (f"; {failed} not modelled (see summary.csv)" if failed else "")
    )
