"""The one rule by which ``activebonds auto`` keeps a model: every candidate's run scored on
the validation frames (the tail of the fitted frames, never the held-out ones), one step at
each marker and ``--ahead`` frames ahead overall, beside zero force; a candidate is better
where fewer markers are worse than zero force one step, then where it predicts ``--ahead``
frames ahead closer. Where the marker noise dominates the one-step score (the recording
smoothed for the structure: :func:`~.structure.noise_of_fitted`), the frames-ahead score comes
first: one step, a marker is better or worse than zero force by its noise, not by the
model."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from pathlib import Path

RULE = (
    "on the validation frames, fewer markers worse than zero force one step, then a lower "
    "RMS frames ahead (where the marker noise dominates one step: the RMS frames ahead first)"
)


@dataclass(frozen=True)
class Judged:
    """A run's best model scored on the validation frames ``frames`` (errors in mm): one
    step overall and at each marker, and ``horizon`` frames ahead, each beside zero force's."""

    frames: tuple[int, int]
    horizon: int
    one_step_mm: float
    zero_force_one_step_mm: float
    worse: int  # markers where the model is not better than zero force, one step
    markers: int  # markers judged
    ahead_mm: float
    zero_force_ahead_mm: float
    noisy: bool = False  # the marker noise dominates one step: frames ahead first

    def record(self) -> dict:
        out = asdict(self)
        out["frames"] = list(self.frames)
        return {k: (v if not isinstance(v, float) or math.isfinite(v) else None) for k, v in
                out.items()}  # fmt: skip


def finite_or_inf(x: float) -> float:
    """``x``, or infinity where it is not a finite number (a failed prediction ranks last)."""
    return x if isinstance(x, int | float) and math.isfinite(x) else math.inf


def _ahead_first(new: Judged, old: Judged) -> bool:
    """Whether the frames-ahead score decides: where the noise dominates one step and the
    two differ there."""
    ahead = finite_or_inf(new.ahead_mm), finite_or_inf(old.ahead_mm)
    return (new.noisy or old.noisy) and ahead[0] != ahead[1]


def better(new: Judged, old: Judged) -> bool:
    """Whether ``new`` is the better model: fewer markers worse than zero force one step,
    then (as many) a lower RMS ``horizon`` frames ahead (a non-finite one is no better than
    any); where the noise dominates one step (``noisy``), the RMS ahead first."""
    if new.worse != old.worse and not _ahead_first(new, old):
        return new.worse < old.worse
    return finite_or_inf(new.ahead_mm) < finite_or_inf(old.ahead_mm)


def compared(new: Judged, old: Judged, old_name: str) -> str:
    """Why ``new`` is or is not better than ``old`` (the run ``old_name``), in words: the
    first of the rule's two scores that differs."""
    if new.worse != old.worse and not _ahead_first(new, old):
        return f"{new.worse} marker(s) worse than zero force one step, {old_name} {old.worse}"
    return f"{new.horizon} ahead {new.ahead_mm:.4g} mm, {old_name} {old.ahead_mm:.4g} mm"


def judged_of(evaluation, noisy: bool = False) -> Judged:
    """An :class:`~activebonds.report.evaluate.Evaluation` (one step, then frames ahead) as
    the rule reads it; ``noisy``: the marker noise dominates one step."""
    one, ahead = evaluation.comparisons[0], evaluation.comparisons[-1]
    return Judged(
        frames=tuple(evaluation.frames),
        horizon=int(ahead.horizon),
        one_step_mm=float(one.model_mm),
        zero_force_one_step_mm=float(one.zero_force_mm),
        worse=len(one.worse_markers()),
        markers=sum(v.judged for v in one.per_marker.values()),
        ahead_mm=float(ahead.model_mm),
        zero_force_ahead_mm=float(ahead.zero_force_mm),
        noisy=noisy,
    )


def judge(ws, run_path: Path) -> Judged:
    """The run's best model evaluated on ``ws``'s validation frames of the recording (one
    step and ``--ahead`` frames ahead; the model's time from the fitted frames' first)."""
    from ..identify.rundir import RunDir
    from ..model import load_model
    from ..report.evaluate import evaluate

    model = load_model(RunDir(run_path).best_model_path)
    found = evaluate(
        model,
        ws.recording,
        frames=ws.split.validation,
        horizon=ws.options.ahead,
        origin=ws.split.fitted[0],
    )
    return judged_of(found, noisy=bool(ws.noise.window))
