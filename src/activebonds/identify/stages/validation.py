"""The validation stage (``fit --validate START:STOP``, ``FitSettings.validation``): the model
and the zero-force predictor on frames of the recording the fit did not use: one-step RMS,
free-run RMS and frames within 50 mm (:func:`activebonds.identify.judge.metrics.validation_record`).
"""

from __future__ import annotations

import numpy as np

from ...document import Section
from ..judge.metrics import read_validation, validation_record
from ..judge.verdict import comparisons_from
from ..judge.verdict import lines as verdict_lines
from .base import Fit, Outcome
from .baselines import metrics_line, verdict_columns

NAME = "validation"


class ValidationStage:
    name = NAME
    state = None

    def doing(self, fit: Fit) -> str:
        return "measuring the model on the validation frames"

    def applies(self, fit: Fit) -> bool:
        return fit.completed and fit.held_out is not None and np.isfinite(fit.genome).all()

    def run(self, fit: Fit, saved: dict | None, arrays: dict) -> Outcome:
        s, held = fit.settings, fit.held_out
        start = int(s.validation[0])
        frames = (start, start + held.n_frames)
        return Outcome(validation_record(fit.model, held, s, frames))

    def lines(self, record: dict) -> list[str]:
        frames, found = read_validation(record)
        label = f"validation frames {frames[0]}:{frames[1]}"
        judged = comparisons_from(record.get("judged"))
        return [metrics_line(label, found), *verdict_lines(f"held-out {label}", judged)]

    def sections(self, record: dict, report) -> list[Section]:
        return []  # shown in the free-run table of the report's summary, beside the fit's

    def columns(self, record: dict) -> dict:
        _, found = read_validation(record)
        m, z = found["model"], found["zero_force"]
        return {
            "validation_one_step_rms_mm": m.one_step_rms_mm,
            "validation_zero_force_rms_mm": z.one_step_rms_mm,
            "validation_free_run_rms_mm": m.free_run_rms_mm,
            **verdict_columns("held_out", record),
        }


STAGE = ValidationStage()
