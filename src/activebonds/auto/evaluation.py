"""Steps 4 and 5 of ``activebonds auto``: the kept model evaluated on the held-out frames and
on the fitted ones (``OUT/evaluation.json``), and its report (``OUT/report.html``) with how
it was made."""

from __future__ import annotations

import json
from pathlib import Path

from .folder import BURN_IN, Folder, Options, Windows
from .notes import noise_line


def evaluations(run: Path, recording, split: Windows, options: Options):
    """Two thunks: the kept run's model evaluated on the held-out frames and on the fitted
    ones, the model's time from the fitted frames' first (a drive's phase tracked from
    there)."""

    def on(frames, burn_in=None):
        def evaluate_there():
            from ..identify.judge.burn_in import burn_in_starts
            from ..identify.rundir import RunDir
            from ..model import load_model
            from ..report.evaluate import evaluate

            model = load_model(RunDir(run).best_model_path)
            after = None  # free runs after a burn-in, where the frames have a start for one
            if burn_in is not None:
                seen = recording.select(list(model.markers)).window(*frames).positions
                after = burn_in if burn_in_starts(seen, burn_in, 1, 1) else None
            return evaluate(
                model, recording, frames=frames, horizon=options.ahead, burn_in=after,
                origin=split.fitted[0],
            )  # fmt: skip

        return evaluate_there

    return on(split.held_out, BURN_IN), on(split.fitted)


def write_evaluation(folder: Folder, held, fitted) -> str:
    from ..atomic import write_text_atomic

    record = {"held_out": held.record(), "fitted": fitted.record()}
    write_text_atomic(folder.evaluation, json.dumps(record, indent=2) + "\n")
    one = held.comparisons[0]
    return (
        f"held out, one step: {one.model_mm:.4g} mm (zero force {one.zero_force_mm:.4g} mm): "
        f"{folder.evaluation}"
    )


def how_made(state: dict) -> list[str]:
    """How the kept model was made, for the report: the noise's line, the first three steps'
    notes, the table of the candidates tried (kept or not, and why), the gait candidate's
    rhythm and variants, the walk candidate's stride and floor, the masses' note."""
    from ..data.smoothing import Noise
    from . import table

    steps = state["steps"]
    out = [noise_line(Noise(**state["noise"]))] if "noise" in state else []
    out += [f"{name}: {steps[name]['note']}" for name in ("scaffold", "structure", "fit")
            if name in steps]  # fmt: skip
    out += table.lines(steps.get("fit", {}).get("candidates", []))
    gait = steps.get("fit", {}).get("gait")
    if isinstance(gait, list):  # a run from before the rhythm was recorded: its variants
        gait = {"notes": [], "variants": gait, "chosen": "(not recorded)"}
    if gait:  # the gait candidate's rhythm, its variants judged and the one chosen
        out += [f"gait: {line}" for line in gait["notes"]]
        out += [f"gait variant on the fitted frames' second half: {v}" for v in gait["variants"]]
        out.append(f"gait chosen: {gait['chosen']}")
    walk = steps.get("fit", {}).get("walk")
    if walk:  # the walk candidate's stride and floor, and its model
        out += [f"walk: {line}" for line in walk["notes"]]
        out.append(f"walk model: {walk['variant']}")
    if steps.get("fit", {}).get("masses"):
        out.append(steps["fit"]["masses"])
    return out


def write_html(run: Path, report: Path, frames: int, evaluation: Path, made=()) -> str:
    """The run's report, its held-out verdicts (one step and K ahead) the evaluation's,
    ``made`` (:func:`how_made`) a section of its own."""
    from ..report import write_report
    from ..report.html import Beyond

    held = json.loads(evaluation.read_text(encoding="utf-8"))["held_out"]
    beyond = Beyond.from_record(held)
    return str(write_report(run, report, frames=frames, beyond=beyond, made=made))
