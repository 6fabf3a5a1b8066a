"""The uncertainty stage: the Gauss-Newton standard errors and 95 % intervals of the free
parameters at the fit's optimum, on the cost of its last accepted refinement stage (the
search's cost without one) (:mod:`activebonds.identify.judge.uncertainty`). RUN/uncertainty.csv
(one row per parameter) and uncertainty.json; a fit whose report cannot be formed says why."""

from __future__ import annotations

import numpy as np

from ...data.smoothing import noise_of
from ...document import Section, Table
from ...model.names import labeller
from .. import costs
from ..judge import integrator_check, modes, uncertainty
from .base import Fit, Outcome

NAME = "uncertainty"


class UncertaintyStage:
    name = NAME
    state = None

    def doing(self, fit: Fit) -> str:
        return "estimating the uncertainty of the parameters"

    def applies(self, fit: Fit) -> bool:
        return fit.run is not None and fit.completed and np.isfinite(fit.genome).all()

    def run(self, fit: Fit, saved: dict | None, arrays: dict) -> Outcome:
        stages, states = fit.products.get("refine", ([], None))
        last = next((s for s in reversed(stages) if s.accepted), None)
        horizon = last.horizon if last else fit.settings.es_horizon
        cost = last.cost if last else costs.DEFAULT
        try:
            report = uncertainty.estimate(
                fit.ident, fit.settings, fit.genome, horizon, cost, states
            )
        except (MemoryError, ValueError, np.linalg.LinAlgError) as err:
            return Outcome({"not_computed": str(err)}, files={"csv": None})
        record = report.record()
        checked = None
        if integrator_check.applies(fit.settings):  # are the integrator's steps enough?
            checked = integrator_check.check(
                fit.ident, fit.settings, fit.genome, horizon, report.estimates, report.cost, states
            )
            record["substeps_check"] = (
                checked.record() if hasattr(checked, "record") else {"not_made": checked}
            )
        fastest = None
        if not hasattr(checked, "warning"):  # no finer-substeps check: the springs' modes
            try:  # a diagnostic: whatever it meets, the fit's uncertainty stands
                fastest = fastest_mode(fit)
            except (ValueError, TypeError, ArithmeticError, np.linalg.LinAlgError) as err:
                record["fastest_mode"] = {"not_computed": str(err)}
            if fastest is not None:
                record["fastest_mode"] = {"omega": fastest[0], "dt": fastest[1]}
        record["warnings"] = uncertainty.warnings(
            cost,
            horizon,
            fit.settings.substeps,
            uncertainty.shooting_rejected(stages),
            checked,
            None if fastest is None else modes.warning(*fastest, fit.settings.substeps),
        )
        said = checked.warning() if hasattr(checked, "warning") else None
        if said and report.sigma_mm < integrator_check.EXACT_MM:  # an exact fit: no refit
            exact = integrator_check.exact_warning(checked, report.sigma_mm)
            record["warnings"] = [exact if w == said else w for w in record["warnings"]]
        noise = marker_noise(fit.ident.all_data)
        record["noise_mm"] = noise
        found = uncertainty.misfit(report.sigma_mm, noise, report.cost, horizon)
        if found:  # first: a misfit outweighs every other caveat of the intervals
            record["warnings"].insert(0, found)
        return Outcome(record, files={"csv": report.csv_text()})

    def lines(self, record: dict) -> list[str]:
        if "not_computed" in record:
            return [f"uncertainty: not computed ({record['not_computed']})"]
        est = record["estimates"]
        ok = sum(e["determined"] for e in est)
        return [
            f"uncertainty: {ok} of {len(est)} parameters determined, 95 % intervals (from the "
            f"{record['cost']} cost, horizon {record['horizon']}) in uncertainty.csv",
            *(f"uncertainty: warning: {w}" for w in record.get("warnings", [])),
            *checked_line(record.get("substeps_check")),
        ]

    def sections(self, record: dict, report) -> list[Section]:
        return [section(record, report.run.model.spec)]

    def columns(self, record: dict) -> dict:
        if "not_computed" in record:
            return {}
        est = record.get("estimates", [])
        return {"determined_parameters": sum(bool(e["determined"]) for e in est)}


MODE_FRAMES = 20  # recorded configurations the fitted forces are linearised at, at most


def fastest_mode(fit: Fit) -> tuple[float, float] | None:
    """(the fitted forces' fastest angular frequency, the frame interval) over up to
    :data:`MODE_FRAMES` frames with every marker, spread over the fitted window
    (:func:`.modes.fastest`), or None where no frame has them all."""
    data = fit.ident.data
    whole = np.flatnonzero(np.asarray(data.mask, bool).all(axis=1))
    if whole.size == 0:
        return None
    frames = whole[np.unique(np.linspace(0, whole.size - 1, MODE_FRAMES).round().astype(int))]
    model = fit.ident.model.with_genome(np.asarray(fit.genome, np.float64))
    return modes.fastest(model, np.asarray(data.positions)[frames]), float(data.dt)


def marker_noise(recordings) -> float:
    """The markers' noise per coordinate (mm, fourth differences: :func:`.noise_of`), pooled
    over the recordings by frames."""
    frames = np.array([r.positions.shape[0] for r in recordings], np.float64)
    sigma = np.array([noise_of(r.positions).sigma for r in recordings], np.float64)
    return float(np.sqrt(np.sum(frames * sigma**2) / np.sum(frames)))


def checked_line(check: dict | None) -> list[str]:
    """The substeps check in one line where it found nothing to warn about."""
    if not check or "not_made" in check or check["moved"]:
        return []
    return [
        f"uncertainty: checked at --substeps {check['substeps']}: every parameter moves by less "
        f"than its 95 % interval (at most {check['largest_sd']:.2f} standard errors, "
        f"{check['parameter']})"
    ]


def section(rec: dict, spec) -> Section:
    """Each free parameter with its standard error and 95 % interval, or "not determined"
    and why (never a huge interval)."""
    if "not_computed" in rec:
        text = [f"Not computed: {rec['not_computed']}."]
        return Section("Uncertainty", text=text, anchor="uncertainty")
    rows = []
    label = labeller(spec)
    for e in rec.get("estimates", []):
        name = e.get("label") or label(e["name"])
        if e["determined"]:
            rows.append((name, e["value"], e["std_error"], f"{e['low']:.6g} – {e['high']:.6g}", ""))
        else:
            rows.append((name, e["value"], "not determined", "not determined", e["note"]))
    condition = rec.get("condition")
    sigma = rec["sigma_mm"]
    text = [
        f"Gauss-Newton covariance at the optimum on the {rec['cost']} cost (horizon "
        f"{rec['horizon']}): {rec['residuals']} residual coordinates, {rec['variables']} "
        f"variables, rank {rec['rank']}, condition number "
        f"{'infinite' if condition is None else f'{condition:.3g}'} (columns scaled), residual "
        f"standard deviation {sigma if sigma is None else round(sigma, 6)} mm per coordinate.",
        "The intervals assume independent Gaussian marker noise and an output-error cost "
        "(shooting or a free run); on the one-step cost with noisy markers the optimum itself "
        "is biased and no interval describes that.",
    ]
    text += [f"Warning: {w}." for w in rec.get("warnings", [])]
    text += [
        line.removeprefix("uncertainty: ").capitalize() + "."
        for line in checked_line(rec.get("substeps_check"))
    ]
    text += [f"Not determined: {d}." for d in rec.get("directions", [])]
    table = Table(("parameter", "value", "standard error", "95 % interval", "note"), rows)
    return Section("Uncertainty", text=text, tables=[table], anchor="uncertainty")


STAGE = UncertaintyStage()
