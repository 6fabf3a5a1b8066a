"""One subject's model judged on a trial it never saw: ``activebonds auto A B C --subject``.

After the dataset's trials are ``auto``'d one by one (:mod:`.dataset`), each trial is left out
in turn: a model of the subject is fitted on all the other trials at once (as ``fit MODEL A
B`` fits several recordings: their costs added) and judged on the left-out trial's held-out
frames (its last share, which its own ``auto`` never fitted either), one step and ``--ahead``
frames ahead, beside zero force and beside that trial's own model on the same frames.

The subject's model is evaluated with the fit's integration step (more substeps on a trial
recorded at a lower rate). It is the spring body ``auto``'s structure step decided on the first of the
other trials (``<trial>/structure.toml``: its springs, masses and anchors), every free
parameter fitted on all the other trials, from that trial's exact optimum, on the one-step
cost. Trials that were not modelled, that lack one of that model's markers or whose frame
rate is not the other trials' are left out of the fit, each with one line.

Written: ``OUT/subject/<left-out trial>/`` (the subject model's run) and
``OUT/subject.csv``, a row per left-out trial.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable
from pathlib import Path

from .dataset import Trial, _num

COLUMNS = (
    "left_out", "fitted_on", "held_out_frames", "ahead",
    "subject_one_step_mm", "trial_model_one_step_mm", "zero_force_one_step_mm",
    "subject_one_step_verdict",
    "subject_ahead_mm", "trial_model_ahead_mm", "zero_force_ahead_mm", "subject_ahead_verdict",
    "message",
)  # fmt: skip


def leave_one_out(items: list[Trial], out: Path, options, rows: dict[str, dict],
                  say: Callable[[str], None]) -> list[dict]:  # fmt: skip
    """Every modelled trial left out in turn (see the module's docstring); the rows, also
    written to ``out/subject.csv``."""
    from ..data import read_trajectory

    done = [t for t in items if rows.get(t.name, {}).get("status") == "done"]
    recordings = {t.name: read_trajectory(t.path) for t in done}
    result = []
    for left in done:
        others = [t for t in done if t is not left]
        result.append(_left_out(left, others, recordings, out, options, rows[left.name], say))
        _write(out / "subject.csv", result)
    return result


def _usable(others: list[Trial], recordings: dict, markers, rate: float, say) -> list[Trial]:
    kept = []
    for t in others:
        rec = recordings[t.name]
        missing = [m for m in markers if m not in rec.markers]
        if missing:
            say(f"subject: {t.name} left out of the fit: it has no marker {', '.join(missing)}")
        elif abs(rec.rate - rate) > 1e-9 * rate:
            say(f"subject: {t.name} left out of the fit: {rec.rate:g} Hz, not {rate:g} Hz")
        else:
            kept.append(t)
    return kept


def _left_out(left: Trial, others, recordings, out: Path, options, own: dict, say) -> dict:
    from ..identify import fit
    from ..identify.settings import FitSettings
    from ..model import load_model
    from ..report.evaluate import evaluate

    row = dict.fromkeys(COLUMNS, "")
    row["left_out"] = left.name
    source = next((t for t in others if (out / t.name / "structure.toml").is_file()), None)
    if source is None:
        row["message"] = "no other modelled trial to fit the subject's model on"
        return row
    model = load_model(out / source.name / "structure.toml")
    rate = recordings[source.name].rate
    fitted_on = _usable(others, recordings, model.markers, rate, say)
    row["fitted_on"] = " ".join(t.name for t in fitted_on)
    test = recordings[left.name]
    missing = [m for m in model.markers if m not in test.markers]
    if missing:
        row["message"] = f"the left-out trial has no marker {', '.join(missing)}"
        return row
    settings = FitSettings(
        population=options.population, generations=options.generations, seed=options.seed,
        init="model", cost="restart", horizon=(1,),
    )  # fmt: skip
    data = [recordings[t.name].select(list(model.markers)) for t in fitted_on]
    (out / "subject").mkdir(exist_ok=True)
    result = fit(model, data, settings, out=out / "subject" / left.name, overwrite=True)
    a, b = (int(x) for x in own["held_out_frames"].split(":"))
    # the fit's integration step kept at the left-out trial's rate (a model identified with
    # Euler steps of 1/60 s carries them in its parameters: at 30 Hz, two substeps)
    substeps = max(1, round(rate * settings.substeps / test.rate))
    ev = evaluate(result.model, test, markers=list(model.markers), frames=(a, b),
                  substeps=substeps, integrator=settings.integrator,
                  horizon=options.ahead)  # fmt: skip
    row["held_out_frames"], row["ahead"] = own["held_out_frames"], options.ahead
    for comp, prefix in zip(ev.comparisons[:2], ("one_step", "ahead"), strict=False):
        row[f"subject_{prefix}_mm"] = _num(comp.model_mm)
        row[f"zero_force_{prefix}_mm"] = _num(comp.zero_force_mm)
        row[f"subject_{prefix}_verdict"] = comp.overall.word
        row[f"trial_model_{prefix}_mm"] = own[f"{prefix}_mm"]
    say(
        f"subject: {left.name} left out, the model fitted on {row['fitted_on']}: one step "
        f"{row['subject_one_step_mm']} mm (its own model {row['trial_model_one_step_mm']} mm, "
        f"zero force {row['zero_force_one_step_mm']} mm, {row['subject_one_step_verdict']})"
    )
    return row


def _write(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(buf.getvalue(), encoding="utf-8")
    tmp.replace(path)
