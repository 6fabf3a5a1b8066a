"""The one-run report's tables (the run at a glance, its errors beside zero force's, its free
runs, its parameters, its neurons) and its verdicts in words, the frames beyond the fit scored
as ``evaluate`` scores them; :func:`fmt`, how a number reads in a table."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..document import Marked, Table
from ..errors import InputError
from ..identify.judge.ahead import DEFAULT_AHEAD
from ..identify.judge.ahead import comparisons as ahead_comparisons
from ..identify.judge.baselines import zero_force_predictions
from ..identify.judge.burn_in import BurnIn
from ..identify.judge.metrics import FreeRunMetrics
from ..identify.judge.predictions import rms_mm
from ..identify.judge.verdict import Comparison, comparisons_from, free_run_advice, verdict
from ..identify.judge.verdict import lines as verdict_lines
from ..identify.stages import baselines, validation
from ..model.names import parameter_rows
from .predict import Prediction
from .runs import RunRecord

_OPTIMIZERS = {"es": "the paper's evolution strategy (es)", "random": "random search (random)"}


def fmt(x: object, digits: int = 4) -> str:
    """Numbers to short text (NaN/None as an em dash); other values as str."""
    if x is None:
        return "—"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int | np.integer):
        return str(int(x))
    if isinstance(x, float | np.floating):
        if not math.isfinite(float(x)):
            return "—" if math.isnan(float(x)) else ("∞" if x > 0 else "−∞")
        return f"{float(x):.{digits}g}"
    return str(x)


def _markers_text(pred: Prediction) -> str:
    return ", ".join(
        n if n == m else f"{n} ← {m}" for n, m in zip(pred.names, pred.markers, strict=True)
    )


def summary_table(record: RunRecord, pred: Prediction) -> Table:
    """The run at a glance: inputs, settings, outcome, versions, wall time."""
    meta, st, s = record.meta, record.status, record.settings
    inputs = meta.get("inputs", {})
    w = record.window
    start = s.frames[0]
    gens_done = int(st.get("generation", len(record.history.get("generation", []))))
    per = ", ".join(
        f"{n} {fmt(v, 3)}" for n, v in zip(pred.names, pred.one_step_rms_mm, strict=True)
    )
    versions = ", ".join(f"{k} {v}" for k, v in sorted(meta.get("versions", {}).items()))
    be = meta.get("backend", {})
    wall = st.get("wall_seconds")
    rows = [
        ("run", str(record.path)),
        ("status", st.get("status", "unknown") + ("" if record.has_best else " (no best model)")),
        ("model", f"{record.model.name} ({inputs.get('model', {}).get('path', 'in memory')})"),
        ("bond variant", s.bonds),
        ("mass scale fixed by", record.model.spec.mass_scale()),
        ("data", inputs.get("data", {}).get("path", w.source or "in memory")),
        ("markers (particle ← marker)", _markers_text(pred)),
        (
            "frames fitted",
            f"{start}:{start + w.n_frames} ({w.n_frames} frames, {w.duration:.4g} s)",
        ),
        ("rate", f"{w.rate:g} Hz"),
        ("optimizer", _OPTIMIZERS.get(s.optimizer, s.optimizer)),
        ("population", s.population),
        ("generations", f"{gens_done} of {s.generations}"),
        ("seed", s.seed),
        (
            "cost",
            f"horizon {s.es_horizon}, {s.es_integrator} with {s.es_substeps} substep(s), {s.precision}",
        ),
        ("refinement", _refinement_text(s)),
        ("best RMS error (fit cost)", f"{fmt(st.get('best_rms_mm'))} mm"),
        ("best RMS per particle (one-step)", f"{per} mm"),
        ("failed evaluations", st.get("failed_evaluations", "—")),
        (
            "wall time (the run's, every session)",
            "—" if wall is None else f"{float(wall):.4g} s",
        ),
        ("versions", versions),
        ("backend", f"{be.get('backend', '?')} ({be.get('platform', '?')}), x64 {be.get('x64')}"),
        ("created", meta.get("created", "—")),
        ("command", meta.get("command", "—")),
    ]
    return Table(columns=("", ""), rows=rows, key_value=True, caption="Run")


def _refinement_text(s) -> str:
    if s.refine == "none":
        return "none"
    horizons = ", ".join(str(h) for h in s.horizon)
    return f"Levenberg-Marquardt (optimistix), {s.cost} cost, horizons {horizons}"


WORSE = "not better than zero force"


def _judged(model_mm: float, zero_mm: float):
    """The model's number, marked (red) where it does not beat zero force."""
    v = verdict(model_mm, zero_mm)
    return Marked(float(model_mm), v.text()) if v.better is False else model_mm


def zero_force_one_step_mm(pred: Prediction) -> tuple[np.ndarray, np.ndarray | None]:
    """The zero-force predictor's one-step RMS (mm) per particle on the terms of the model's
    (:attr:`Prediction.one_step_rms_mm`), over the fitted frames and beyond them."""
    one, _ = zero_force_predictions(pred.recorded, 1)
    fit, n = pred.fit_frames, pred.n_frames
    beyond = rms_mm(one, pred.recorded, slice(fit, n)) if n > fit else None
    return rms_mm(one, pred.recorded, slice(0, fit)), beyond


def errors_table(
    pred: Prediction,
    caption: str = "RMS position error per particle (mm)",
    beyond: Beyond | None = None,
) -> Table:
    """Per particle, the model's one-step and free-run RMS beside zero force's one-step RMS,
    on the fitted frames and beyond them; red where the model is not better. With ``beyond``
    (the frames beyond scored as ``evaluate`` scores them), its one step and K frames ahead
    beyond the fit, each beside zero force's."""
    zero_fit, zero_beyond = zero_force_one_step_mm(pred)
    cols = ["particle", "marker", "one-step (fit)", "zero force (fit)", "free run (fit)"]
    scored = beyond.comparisons if beyond is not None and pred.extended else ()
    if pred.extended:
        cols += ["one-step (beyond)", "zero force (beyond)", "free run (beyond)"]
    for c in scored[1:]:
        cols += [f"{c.horizon} ahead (beyond)", f"zero force {c.horizon} ahead (beyond)"]
    rows = []
    for p, (n, m) in enumerate(zip(pred.names, pred.markers, strict=True)):
        one = float(pred.one_step_rms_mm[p])
        row = [n, m, _judged(one, zero_fit[p]), float(zero_fit[p]), float(pred.free_run_rms_mm[p])]
        if pred.extended:
            one, zero = float(pred.one_step_rms_mm_beyond[p]), float(zero_beyond[p])
            if scored:  # evaluate's terms, as the verdict beyond
                one, zero = scored[0].model_per_marker[p], scored[0].zero_force_per_marker[p]
            row += [_judged(one, zero), zero, float(pred.free_run_rms_mm_beyond[p])]
        for c in scored[1:]:
            row += [
                _judged(c.model_per_marker[p], c.zero_force_per_marker[p]),
                c.zero_force_per_marker[p],
            ]
        rows.append(row)
    caption += f"; red: {WORSE} (the constant-velocity predictor, same terms)"
    if pred.extended:
        caption += (
            "; beyond: the frames after the fitted ones as a window of their own, as "
            "evaluate --frames scores them (the free run from their first two frames"
            + (
                ", the one-step and K-ahead predictions from their third frame on)"
                if scored
                else ")"
            )
        )
    return Table(columns=cols, rows=rows, caption=caption)


@dataclass(frozen=True)
class Beyond:
    """The frames beyond the fit scored as ``evaluate --frames START:STOP --horizon K`` scores
    them (:func:`~activebonds.identify.judge.ahead.comparisons`): their frames [start, stop) of the
    recording and the comparisons, one step then K frames ahead, overall and per marker."""

    frames: tuple[int, int]
    comparisons: tuple[Comparison, ...]
    burn_in: BurnIn | None = None  # free runs after a burn-in there, where scored

    @classmethod
    def from_record(cls, record: dict) -> Beyond:
        """From an evaluation's record (:meth:`.evaluate.Evaluation.record`, as ``auto``'s
        evaluation.json keeps its held-out one)."""
        a, b = record["frames"]
        after = BurnIn.from_record(record["burn_in"]) if "burn_in" in record else None
        return cls((int(a), int(b)), tuple(comparisons_from(record["comparisons"])), after)

    def lines(self) -> list[str]:
        a, b = self.frames
        after = self.burn_in.lines() if self.burn_in is not None else []
        return verdict_lines(f"frames beyond the fit {a}:{b}", self.comparisons) + after


def beyond_scores(record: RunRecord, pred: Prediction, horizon: int = DEFAULT_AHEAD) -> Beyond:
    """The frames the report predicts beyond the fitted window, scored by ``evaluate``'s code
    as ``evaluate RUN/best_model.toml DATA --frames START:STOP --horizon HORIZON`` scores them:
    a window of their own (the first prediction from their first two frames; the model's time
    starting at their first frame), the run's substeps and integrator."""
    from ..data import Trajectory

    s, fit = record.settings, pred.fit_frames
    rec = pred.recorded[fit:]
    window = Trajectory(rec, np.isfinite(rec).all(axis=-1), pred.markers, 1.0 / pred.dt)
    found = ahead_comparisons(
        record.model, window, horizon, substeps=s.substeps, method=s.integrator
    )
    start = int(s.frames[0])
    return Beyond((start + fit, start + pred.n_frames), tuple(found))


def verdict_text(record: RunRecord, pred: Prediction, beyond: Beyond | None = None) -> list[str]:
    """The verdicts in words (:mod:`activebonds.identify.judge.verdict`): on the fitted frames and,
    after ``fit --validate``, the validation frames (one step and K frames ahead, overall and
    per marker, as ``fit`` printed them), and on the frames beyond the fitted window
    (``beyond``: one step and K frames ahead, as ``evaluate`` scores them)."""
    out = []
    fitted = record.records.get(baselines.NAME, {})
    out += verdict_lines("fitted frames", comparisons_from(fitted.get("judged")))
    if "fitted" in fitted:
        run = FreeRunMetrics.from_dict(fitted["fitted"]["model"]).free_run_rms_mm
        out += [a for a in (free_run_advice(run, fitted.get("holds")),) if a is not None]
    held = record.records.get(validation.NAME)
    if held is not None and "judged" in held:
        a, b = held["frames"]
        out += verdict_lines(f"validation frames {a}:{b}", comparisons_from(held["judged"]))
    if beyond is not None:
        out += beyond.lines()
    return out


def free_run_table(record: RunRecord) -> Table | None:
    """One-step RMS, free-run RMS and frames within the threshold
    (:func:`activebonds.identify.judge.metrics.free_run_metrics`) of the model and the zero-force
    predictor on the fitted frames and, after ``fit --validate``, on the validation frames,
    as the baselines and validation stages recorded them."""
    s = record.settings
    start = s.frames[0]
    fitted = record.records.get(baselines.NAME, {}).get("fitted")
    if fitted is None:
        return None
    rows = baselines.free_run_rows(f"fitted {start}:{start + record.window.n_frames}", fitted)
    held = record.records.get(validation.NAME)
    if held is not None:
        frames = held["frames"]
        rows += baselines.free_run_rows(f"validation {frames[0]}:{frames[1]}", held)
    threshold = FreeRunMetrics.from_dict(fitted["model"]).threshold_mm
    return Table(
        (
            "",
            "frames",
            "one-step RMS (mm)",
            "free-run RMS (mm)",
            f"frames within {threshold:g} mm (median)",
            "starts",
        ),
        rows,
        "Free run. Free-run RMS: one run from the window's first two frames. Frames within "
        f"{threshold:g} mm: free runs from several start frames (spread over the window's "
        "first half), each counted until its worst marker is first off by more than "
        f"{threshold:g} mm; the median over starts, '>=' when runs reached the window's end "
        "first (censored). Zero force: constant velocity from the two start frames.",
    )


def searched_model(record: RunRecord):
    """The model whose bounds the fit searched: the run's input model (a best model written
    without min/max derives new bounds around its values); the best model if it is gone."""
    from ..identify.problem import variant
    from ..identify.rundir import RunDir

    try:
        return variant(RunDir(record.path).input_model(), record.settings.bonds)
    except (InputError, ValueError):
        return None


def parameters_table(record: RunRecord, searched=None) -> Table:
    """Each free parameter by its readable name, its value, search bounds, and "near min" or
    "near max" within 1 % of a bound (names.NEAR_BOUND); the machine key last."""
    rows = [
        (r.name, r.value, r.lower, r.upper, r.log, r.bound_text(), r.key)
        for r in parameter_rows(record.model, bounds=searched)
    ]
    columns = ("parameter", "value", "min", "max", "log search", "at a bound", "key")
    return Table(columns, rows, "Identified parameters")


def neural_table(pred: Prediction, labels: Sequence[str]) -> Table:
    rows = [("saturated samples (|a| > 0.95) along the free run", pred.saturated_share)]
    for b in np.flatnonzero(pred.neural):
        rows.append((f"  neuron {labels[b]}", float(pred.saturated_per_neuron[b])))
    rows.append(("near-zero weights (|w| < 1 % of the weight range)", pred.near_zero_weight_share))
    return Table(("", ""), rows, "Neurons", key_value=True)
