"""The refinement stage (``fit --refine lm``): Levenberg-Marquardt from the search's best, one
stage per horizon of the curriculum (:mod:`activebonds.identify.solvers.refine`). Each stage is saved
as it ends (RUN/refine.json and refine.npz with the shooting states), so a resumed run
continues with the next one. Ctrl-C between two steps of a stage saves it where it got to
(the record's ``interrupted``: its best genome so far, the shooting states) and ends the fit;
a resumed run continues that stage from there."""

from __future__ import annotations

import time

import numpy as np

from ...document import Section, Table
from .. import costs
from ..solvers.refine import Refinement, Stage, StageInterrupted
from .base import Fit, Outcome

NAME = "refine"


STEP_SECONDS = 1.0  # a stage's step said at most this often


def step_text(doing: str, i: int, n: int, horizon: int, part, steps, max_steps, objective) -> str:
    """What a refinement stage shows while it runs: ``doing`` (the phase's status), then
    `` - `` and where the stage is (the detail a progress display updates in place)."""
    return (
        f"{doing} - stage {i}/{n} (horizon {horizon}), {part}: step {steps}/{max_steps}, "
        f"objective {objective:.4g} m^2"
    )


def _step_lines(fit: Fit, doing: str, i: int, horizon: int):
    """``Refinement.on_step`` saying the stage's steps through ``fit.say`` (None without),
    at most every :data:`STEP_SECONDS`."""
    if fit.say is None:
        return None
    n, last, lowest = len(fit.settings.horizon), [0.0], {}

    def on_step(part, steps, max_steps, objective):
        # the lowest cost met in this part (a rejected trial step's is not where it stands)
        if objective == objective:
            lowest[part] = min(objective, lowest.get(part, objective))
        now = time.monotonic()
        if now - last[0] >= STEP_SECONDS:
            last[0] = now
            shown = lowest.get(part, objective)
            fit.say(step_text(doing, i, n, horizon, part, steps, max_steps, shown))

    return on_step


def costs_line(settings) -> str:
    """Which cost the search and the refinement used, and why, in one line."""
    s = settings
    search = (
        (
            "the search on the one-step cost (1 Euler substep, whose optimum --init lsq solves "
            "exactly; only the shooting's start)"
        )
        if s.es_exact
        else f"the search on the restart cost (horizon {s.es_horizon}, {s.stepper.describe()})"
    )
    refine = costs.get(s.cost).describe(s)
    return f"costs: {search}; {refine}"


class RefinementStage:
    name = NAME
    state = "refining"

    def doing(self, fit: Fit) -> str:
        n = len(fit.settings.horizon)
        return f"refining the best model (Levenberg-Marquardt, {n} stage{'s' * (n > 1)})"

    def applies(self, fit: Fit) -> bool:
        return fit.completed and fit.settings.refine != "none"

    def run(self, fit: Fit, saved: dict | None, arrays: dict) -> Outcome:
        settings, start = fit.settings, [float(g) for g in fit.genome]
        refinement = Refinement(fit.ident, settings)
        stages: list[Stage] = []
        partial = None  # a stage interrupted by Ctrl-C, continued from where it got to
        if (
            saved is not None
            and saved.get("from_generation") == fit.generation
            and saved.get("from_genome") == start
        ):
            stages = [Stage(**r) for r in saved["stages"]][: len(settings.horizon)]
            refinement.states = _states(arrays)
            if saved.get("interrupted") and len(stages) < len(settings.horizon):
                partial = Stage(**saved["interrupted"])
        current = np.asarray(stages[-1].genome) if stages else fit.genome
        if partial is not None:
            current = np.asarray(partial.genome)
        outcome = self._outcome(fit, start, stages, refinement, current)
        for i, horizon in enumerate(settings.horizon[len(stages) :], len(stages) + 1):
            refinement.on_step = _step_lines(fit, self.doing(fit), i, horizon)
            try:
                stage = refinement.stage(horizon, current)
            except StageInterrupted as stop:  # saved where it got to, as the ES's checkpoint
                outcome = self._outcome(fit, start, stages, refinement, current)
                outcome.record["interrupted"] = stop.stage.record()
                if fit.run is not None:
                    fit.run.save_record(NAME, outcome.record, arrays=outcome.arrays)
                raise
            if partial is not None:  # the interrupted stage, continued
                stage.message = (
                    f"continued after an interrupt at step {partial.steps}: {stage.message}"
                )
                stage.steps += partial.steps
                stage.seconds = round(stage.seconds + partial.seconds, 3)
                partial = None
            stages.append(stage)
            current = np.asarray(stage.genome)
            outcome = self._outcome(fit, start, stages, refinement, current)
            if fit.run is not None:  # each stage kept as it ends
                fit.run.save_record(NAME, outcome.record, arrays=outcome.arrays)
        line = _starts(fit, current)
        if line:
            outcome.record["starts"] = line
            if fit.run is not None:
                fit.run.save_record(NAME, outcome.record, arrays=outcome.arrays)
        return outcome

    @staticmethod
    def _outcome(fit: Fit, start, stages, refinement, current) -> Outcome:
        record = {
            "from_generation": fit.generation,
            "from_genome": start,
            "cost": fit.settings.cost,
            "horizons": list(fit.settings.horizon),
            "costs": costs_line(fit.settings),
            "stages": [s.record() for s in stages],
        }
        arrays = {}
        for i, (x, v) in enumerate(refinement.states or ()):  # per recording
            arrays[f"states_x_{i}"], arrays[f"states_v_{i}"] = np.asarray(x), np.asarray(v)
        product = (stages, refinement.states)
        return Outcome(record, genome=np.asarray(current), arrays=arrays, product=product)

    def lines(self, record: dict) -> list[str]:
        """One line per stage: its cost, horizon, RMS before and after, steps."""
        stages = record.get("stages", [])
        out = [record["costs"]] if record.get("costs") else []
        out += [record["starts"]] if record.get("starts") else []
        for i, st in enumerate(stages, 1):
            joined = (
                ""
                if st.get("continuity_mm") is None
                else f", windows join within {st['continuity_mm']:.2g} mm"
            )
            out.append(
                f"refinement {i}/{len(stages)} ({st['cost']}, horizon {st['horizon']}): "
                f"{st['start_rms_mm']:.4g} -> {st['end_rms_mm']:.4g} mm in {st['steps']} steps"
                + (
                    f" ({st['warm_steps']} of them its warm start on the one-step cost)"
                    if st.get("warm_steps")
                    else ""
                )
                + f", {st['seconds']:.3g} s{joined}{_objective(st)}; {st['message']}"
                + (
                    "; raise the limit with fit --max-steps"
                    if "step limit" in st["message"]
                    else ""
                )
            )
        return out

    def sections(self, record: dict, report) -> list[Section]:
        return [Section("Refinement", tables=[table(record)], anchor="refinement")]

    def columns(self, record: dict) -> dict:
        stages = record.get("stages", [])
        return {"refinement_steps": sum(int(s["steps"]) for s in stages)} if stages else {}


def _objective(st: dict) -> str:
    """What the stage's cost adds to its row (a shooting stage whose markers' RMS rose as its
    windows were made to join: both numbers)."""
    return costs.get(st["cost"]).stage_note(st)


def table(record: dict) -> Table:
    """One row per refinement stage: its cost and horizon, the RMS of its own residuals
    before and after, steps, time, and how it ended."""
    rows = [
        (
            i,
            st["cost"],
            st["horizon"],
            st["start_rms_mm"],
            st["end_rms_mm"],
            "—" if st.get("continuity_mm") is None else st["continuity_mm"],
            st["steps"],
            st["seconds"],
            ("" if st["accepted"] else "rejected: ") + st["message"],
        )
        for i, st in enumerate(record.get("stages", []), 1)
    ]
    columns = (
        "stage",
        "cost",
        "horizon",
        "start RMS (mm)",
        "end RMS (mm)",
        "windows join (mm)",
        "steps",
        "seconds",
        "outcome",
    )
    return Table(
        columns,
        rows,
        f"Refinement after generation {record.get('from_generation')} of the ES: each stage "
        "starts from the previous one's result; RMS of the stage's own position residuals.",
    )


def _starts(fit: Fit, genome) -> str | None:
    """The line on the restart states whose start velocity the refinement's substeps could
    not solve at its result (:func:`~activebonds.identify.costs.windows.starts_line`), if any."""
    s = fit.settings
    if s.substeps == 1:
        return None
    from ..costs.windows import join_windows, make_windows, neighbours_of, starts_line

    acting = neighbours_of(fit.ident.model)
    windows = join_windows(
        [make_windows(d.positions, d.mask, d.dt, 1, s.smooth, acting) for d in fit.ident.all_data]
    )
    return starts_line(fit.ident.model, windows, genome, s.substeps, s.integrator)


def _states(arrays: dict) -> list | None:
    n = sum(1 for k in arrays if k.startswith("states_x_"))
    return [(arrays[f"states_x_{i}"], arrays[f"states_v_{i}"]) for i in range(n)] or None


STAGE = RefinementStage()
