"""The gait family on the bundled horse, found as ``activebonds auto`` finds it: no marker
name, frame split or variant is written here (issue 44; the hand-written script of issues 25
and 28 it replaces listed them).

    python scripts/horse_gait.py [--json docs/results/horse_gait.json] [--out runs/gait]

For each gait (the bundled trot and walk, all 7 markers): the variant
:func:`activebonds.auto.gait.choose` picks on frames 0-299 (fitted on 0-149, judged on
150-299; its rhythm, signals, harmonics, coupling and damping from the data alone), solved on
0-299 and judged on the held-out 300-599 as ``activebonds evaluate MODEL DATA --frames
300:600 --origin 0 --horizon 10 --gait --burn-in 10``: one step and 10 ahead beside zero
force, frames within 50 mm, the gait targets against the recording's own values, and the free
runs after a 10-frame burn-in beside the recording's mean gait. Writes the models (``--out``)
and the JSON the tables of docs/EXPERIMENTS.md are written from.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GAITS = {"trot": "horse-trot", "walk": "horse-walk"}
FIT, TEST, AHEAD, BURN_IN = (0, 300), (300, 600), 10, 10


def summary(record: dict) -> dict:
    """The figures of the tables from an evaluation record, model beside zero force."""
    one, ahead = record["comparisons"][0], record["comparisons"][-1]
    gait = record["gait"]
    burn = record["burn_in"]
    return {
        "one_step_mm": one["model_mm"],
        "zero_force_one_step_mm": one["zero_force_mm"],
        "one_step_per_marker_mm": one["model_per_marker_mm"],
        "zero_force_one_step_per_marker_mm": one["zero_force_per_marker_mm"],
        "every_marker_below_zero_force": not one["worse_markers"],
        "ahead_frames": ahead["horizon"],
        "ahead_mm": ahead["model_mm"],
        "zero_force_ahead_mm": ahead["zero_force_mm"],
        "frames_within_50mm": record["model"]["median_frames_within"],
        "zero_force_frames_within_50mm": record["zero_force"]["median_frames_within"],
        "gait": {k: v for k, v in gait["model"].items() if k != "runs"},
        "gait_recording": {k: v for k, v in gait["recording"].items() if k != "runs"},
        "burn_in": {
            k: burn[k] for k in ("frames", "model_within", "zero_force_within", "template_within")
        }
        | {"model_100_mm": burn["model_mm"][-1], "template_100_mm": burn["template_mm"][-1]},
    }


def run_gait(gait: str, out_dir: Path) -> dict:
    from activebonds.auto.gait import choose
    from activebonds.data import read_trajectory
    from activebonds.data.bundled import dataset
    from activebonds.model import build, save_model
    from activebonds.report.evaluate import evaluate

    started = time.time()
    traj = read_trajectory(dataset(GAITS[gait]).path)
    chosen = choose(traj, FIT, AHEAD)
    model = build(chosen.spec)
    out_dir.mkdir(parents=True, exist_ok=True)
    save_model(chosen.spec, out_dir / f"horse_{gait}_gait.toml")
    record = evaluate(
        model, traj, frames=TEST, origin=FIT[0], horizon=AHEAD, gait=True, burn_in=BURN_IN
    ).record()
    held = summary(record)
    passes = dict(held["gait"]["passes"])
    passes["burn_in_within_at_least_template"] = (
        held["burn_in"]["model_within"] >= held["burn_in"]["template_within"]
    )
    passes["every_marker_below_zero_force"] = held["every_marker_below_zero_force"]
    return {
        "gait": gait,
        "markers": list(traj.markers),
        "chosen": chosen.best.variant.text(),
        "notes": list(chosen.notes),
        "variants": [j.line() for j in chosen.judged],
        "held_out": held,
        "passes": passes,
        "tried": {},
        "seconds": round(time.time() - started, 1),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", default=str(ROOT / "docs" / "results" / "horse_gait.json"))
    parser.add_argument("--out", default="runs/gait")
    args = parser.parse_args(argv)
    result = [run_gait(g, Path(args.out)) for g in GAITS]
    Path(args.json).write_text(json.dumps(result, indent=2) + "\n")
    for r in result:
        h = r["held_out"]
        print(
            f"{r['gait']}: {r['chosen']}: one step {h['one_step_mm']:.4g} vs zero force "
            f"{h['zero_force_one_step_mm']:.4g} mm; {sum(r['passes'].values())} of "
            f"{len(r['passes'])} targets"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
