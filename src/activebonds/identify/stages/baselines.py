"""The baselines stage: the fit beside what judges it, on the fitted frames.

The zero-force (constant-velocity) predictor over the fit's own one-step terms (every fitted
recording), the momentum floor of internal-force models and the exact least-squares optimum
of the model's linear family where they apply (the plain one-step cost), and the free-run
metrics of the model and of the zero-force predictor on the first fitted recording
(:mod:`activebonds.identify.judge.baselines`, :mod:`activebonds.identify.judge.metrics`).
"""

from __future__ import annotations

import numpy as np

from ...document import Section, Table
from ...errors import InputError
from ...physics.integrators import Integrator
from ..costs.windows import neighbours_of
from ..judge.ahead import DEFAULT_AHEAD, comparisons
from ..judge.baselines import model_floor_rms_mm, zero_force_rms_mm, zero_force_rms_mm_of
from ..judge.metrics import FreeRunMetrics, censored_text, window_metrics
from ..judge.verdict import comparisons_from, free_run_advice, holds, verdict
from ..judge.verdict import lines as verdict_lines
from .base import Fit, Outcome

NAME = "baselines"
ZERO = "zero force (constant velocity)"
FLOOR = "momentum floor (internal forces)"
LSQ = "exact least squares (this model's family)"


class BaselinesStage:
    name = NAME
    state = None

    def doing(self, fit: Fit) -> str:
        return "measuring the fit beside its baselines (zero force, free runs)"

    def applies(self, fit: Fit) -> bool:
        return fit.completed and np.isfinite(fit.genome).all()

    def run(self, fit: Fit, saved: dict | None, arrays: dict) -> Outcome:
        ident, s = fit.ident, fit.settings
        data = ident.data
        record: dict = {
            "zero_force_rms_mm": zero_force_rms_mm_of(ident.all_data, neighbours_of(ident.model))
        }
        model = fit.model
        if s.es_horizon == 1 and Integrator(s.es_integrator, s.es_substeps).exact_backward:
            record["momentum_floor_rms_mm"] = model_floor_rms_mm(
                model, data.positions, data.mask, data.dt
            )
            record["least_squares_rms_mm"] = _least_squares_rms_mm(model, data)
        found = window_metrics(model, data, s.substeps, s.integrator)
        record["fitted"] = {k: m.to_dict() for k, m in found.items()}
        judged = comparisons(model, data, DEFAULT_AHEAD, substeps=s.substeps, method=s.integrator)
        record["judged"] = [c.to_dict() for c in judged]
        record["holds"] = holds(model, data)
        return Outcome(record)

    def lines(self, record: dict) -> list[str]:
        out = [f"zero-force baseline on the same frames {record['zero_force_rms_mm']:.4g} mm"]
        if "fitted" in record:
            found = _metrics(record["fitted"])
            out.append(metrics_line("fitted frames", found))
            advice = free_run_advice(found["model"].free_run_rms_mm, record.get("holds"))
            if advice is not None:
                out.append(advice)
        out += verdict_lines("fitted frames", comparisons_from(record.get("judged")))
        return out

    def sections(self, record: dict, report) -> list[Section]:
        beyond = report.beyond_one_step
        return [
            Section(
                "Baselines", tables=[table(record, report.prediction, beyond)], anchor="baselines"
            )
        ]

    def columns(self, record: dict) -> dict:
        out = {"zero_force_rms_mm": record.get("zero_force_rms_mm")}
        if "fitted" in record:
            m = FreeRunMetrics.from_dict(record["fitted"]["model"])
            out["free_run_rms_mm"] = m.free_run_rms_mm
            out[f"frames_within_{m.threshold_mm:g}mm"] = m.median_frames_within
            out["frames_within_censored"] = m.median_censored
        out.update(verdict_columns("fitted", record))
        return out


def verdict_columns(prefix: str, record: dict) -> dict:
    """A sweep's columns of a record's comparisons: per horizon, the verdict word, the gain
    over zero force (%) and the markers where the model is not better."""
    out = {}
    for c in comparisons_from(record.get("judged")):
        key = f"{prefix}_{'one_step' if c.horizon == 1 else f'{c.horizon}_ahead'}"
        v = c.overall
        out[f"{key}_verdict"] = v.word
        out[f"{key}_gain_pct"] = v.gain_pct
        out[f"{key}_worse_markers"] = " ".join(c.worse_markers())
    return out


def _least_squares_rms_mm(model, data) -> float | None:
    """The exact least-squares optimum's RMS (mm) of the model's family, where every free
    parameter is linear in the forces (None otherwise, or where it cannot be formed)."""
    from ..costs.windows import make_windows, neighbours_of
    from ..solvers.lsq import least_squares, nonlinear_genes

    if nonlinear_genes(model):
        return None
    try:
        return float(
            least_squares(
                model,
                make_windows(data.positions, data.mask, data.dt, 1, 0, neighbours_of(model)),
            ).rms_mm
        )
    except InputError:
        return None


def _metrics(found: dict) -> dict[str, FreeRunMetrics]:
    return {k: FreeRunMetrics.from_dict(v) for k, v in found.items()}


def metrics_line(label: str, found: dict[str, FreeRunMetrics]) -> str:
    """'fitted frames: one-step RMS ..., free-run RMS ..., frames within 50 mm ...; zero force
    ...' of a model and the zero-force predictor on one window."""
    m, z = found["model"], found["zero_force"]
    return (
        f"{label}: one-step RMS {m.one_step_rms_mm:.4g} mm, free-run RMS "
        f"{m.free_run_rms_mm:.4g} mm, frames within {m.threshold_mm:g} mm "
        f"{m.frames_text()} (median of {len(m.starts)} starts); zero force "
        f"{z.one_step_rms_mm:.4g} mm, {z.free_run_rms_mm:.4g} mm, {z.frames_text()}"
    )


def references(record: dict) -> list[tuple[str, float]]:
    """(name, RMS mm) of the baselines on the fitted frames, for the convergence plot."""
    out = [(ZERO, record.get("zero_force_rms_mm"))]
    if "momentum_floor_rms_mm" in record:
        out.append((FLOOR, record["momentum_floor_rms_mm"]))
    if record.get("least_squares_rms_mm") is not None:
        out.append((LSQ, record["least_squares_rms_mm"]))
    return out


def table(record: dict, pred, scored: tuple[float, float] | None = None) -> Table:
    """The fit beside its baselines (RMS one-step error, mm) on the fitted frames and, where
    the report predicts past them (``pred``), on the frames beyond: as the summary's verdict
    scores them where it has (``scored``: the model's and zero force's, as ``evaluate
    --frames`` scores the frames beyond, a window of their own), else predicted on from the
    fitted frames."""
    fit = pred.fit_frames
    beyond = pred.extended and pred.n_frames - fit >= 1
    model_fit = float(np.sqrt(np.nanmean(pred.one_step_rms_mm**2)))
    model_beyond = float(np.sqrt(np.nanmean(pred.one_step_rms_mm_beyond**2))) if beyond else None
    zero_beyond = None
    if beyond and scored is not None:  # one figure for one run: the summary's
        model_beyond, zero_beyond = (float(x) for x in scored)
    elif beyond:
        rec = pred.recorded[fit - 2 :]
        mask = np.isfinite(rec).all(axis=-1)
        zero_beyond = zero_force_rms_mm(np.where(mask[..., None], rec, np.nan), mask, pred.dt)
    rows = [
        ("this model", model_fit, model_beyond),
        (ZERO, record["zero_force_rms_mm"], zero_beyond),
    ]
    if "momentum_floor_rms_mm" in record:
        rows.append((FLOOR, record["momentum_floor_rms_mm"], None))
    if record.get("least_squares_rms_mm") is not None:
        rows.append((LSQ, record["least_squares_rms_mm"], None))
    rows = [(n, "—" if a is None else a, "—" if b is None else b) for n, a, b in rows]
    judged = [verdict(model_fit, record["zero_force_rms_mm"])]
    judged.append(verdict(model_beyond, zero_beyond) if beyond else None)
    rows.append(("verdict", *(v.text() if v is not None else "—" for v in judged)))
    return Table(
        ("one-step RMS (mm)", "fitted frames", "frames beyond"),
        rows,
        "The fit beside its baselines. A model that does not beat the zero-force predictor on "
        "frames it never saw has learnt nothing that generalises; no model of internal "
        "forces can go below the momentum floor.",
    )


def free_run_rows(label: str, found: dict) -> list[tuple]:
    """Rows of the report's free-run table for one window: the model, then zero force."""
    rows = []
    for name, who in (("model", "this model"), ("zero_force", "zero force")):
        m = FreeRunMetrics.from_dict(found[name])
        rows.append(
            (who, label, m.one_step_rms_mm, m.free_run_rms_mm, m.frames_text(), len(m.starts))
        )
    return rows


STAGE = BaselinesStage()
__all__ = ["STAGE", "censored_text", "metrics_line", "references", "table"]
