"""Score any model on any recording: ``activebonds evaluate`` as a Python function.

:func:`evaluate` cuts the recording to the model's markers and a frame window, as a fit
selects its data (:func:`~activebonds.identify.problem.select_data`), and measures there,
for the model and for the zero-force (constant-velocity) predictor:

* the three numbers of ``fit``'s summary and ``fit --validate``, from the same function
  (:func:`~activebonds.identify.judge.metrics.window_metrics`): one-step RMS (mm), free-run RMS
  (mm) and the median number of frames a free run stays within 50 mm of every marker;
* per particle, the one-step and free-run RMS (mm) over the same terms
  (:func:`~activebonds.report.predict.predict` for the model,
  :func:`~activebonds.report.predict.rms_mm` of the constant-velocity predictions for the
  zero force). Squared and averaged with each particle's count of terms, they give the
  overall numbers back;
* asked for (``body``: a subset of the markers, e.g. a horse's head, withers and sacrum), the
  same three numbers counting only those markers' errors: the free runs of the whole model
  (and of zero force) from the same starts, off once one of *these* markers is off by more
  than the threshold (a swinging hoof does not end a run that holds the body);
* asked for (``gait``), the free runs scored as a gait, insensitive to their phase
  (:mod:`activebonds.report.gait`): period, feet excursions, body distance, cycle RMS;
* one step and ``horizon`` frames ahead (the model's free run from each recorded state, beside
  the zero-force predictor's: :func:`~activebonds.identify.judge.ahead.comparisons`), overall and per
  marker, each with its verdict (:mod:`activebonds.identify.judge.verdict`: better than zero force by
  X %, or worse: the model does not explain this motion).

The model's time starts at the window's first frame (only a model with a rhythmic drive
sees it). Nothing is fitted: a model identified on one trial can be judged on another.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from ..data import Trajectory
from ..errors import InputError, option_error
from ..identify.judge.ahead import DEFAULT_AHEAD, comparisons
from ..identify.judge.burn_in import BurnIn, burn_in, score, targets
from ..identify.judge.metrics import (
    DEFAULT_STARTS,
    THRESHOLD_MM,
    FreeRunMetrics,
    start_frames,
    window_metrics,
)
from ..identify.judge.predictions import rms_mm, zero_force_predictions
from ..identify.judge.verdict import (
    Comparison,
    ParticleScore,
    Score,
    Verdict,
    free_run_advice,
    holds,
)
from ..model import Model
from .gait_runs import GaitEvaluation, gait_evaluation
from .predict import Prediction, predict


@dataclass(frozen=True)
class Evaluation:
    """A model scored on a recorded window (errors in mm)."""

    model_name: str
    source: str  # the recording
    frames: tuple[int, int]  # [start, stop) of the recording
    markers: tuple[str, ...]  # in the model's particle order
    substeps: int
    integrator: str
    model: FreeRunMetrics
    zero_force: FreeRunMetrics
    particles: tuple[ParticleScore, ...]
    comparisons: tuple[Comparison, ...] = ()  # one step, then `horizon` frames ahead
    gait: GaitEvaluation | None = None  # asked for: the free runs scored as a gait
    holds: dict | None = None  # what holds the model (identify.verdict.holds): the advice's
    body_markers: tuple[str, ...] = ()  # asked for: the markers whose errors alone count
    body: dict[str, FreeRunMetrics] | None = None  # their numbers: "model", "zero_force"
    burn_in: BurnIn | None = None  # asked for: free runs after a burn-in, beside zero force

    @property
    def verdict(self) -> Verdict | None:
        """The one-step verdict, overall (None without a comparison)."""
        return self.comparisons[0].overall if self.comparisons else None

    def lines(self) -> list[str]:
        """The verdicts in words: overall and per marker, one step and K frames ahead."""
        a, b = self.frames
        out = [line for c in self.comparisons for line in c.lines(f"frames {a}:{b}")]
        advice = free_run_advice(self.model.free_run_rms_mm, self.holds)
        after = self.burn_in.lines() if self.burn_in is not None else []
        return out + after + ([advice] if advice else [])

    def record(self) -> dict:
        """Plain JSON values (non-finite floats as 'inf', '-inf' or 'nan', as
        :meth:`FreeRunMetrics.to_dict`)."""
        return {
            "model_name": self.model_name,
            "trajectory": self.source,
            "frames": list(self.frames),
            "markers": list(self.markers),
            "substeps": self.substeps,
            "integrator": self.integrator,
            "model": self.model.to_dict(),
            "zero_force": self.zero_force.to_dict(),
            "particles": [p.to_dict() for p in self.particles],
            "comparisons": [c.to_dict() for c in self.comparisons],
            "holds": self.holds,
            **({"gait": self.gait.record()} if self.gait is not None else {}),
            **({"burn_in": self.burn_in.record()} if self.burn_in is not None else {}),
            **(
                {
                    "body": {
                        "markers": list(self.body_markers),
                        **{k: m.to_dict() for k, m in self.body.items()},
                    }
                }
                if self.body is not None
                else {}
            ),
        }


def evaluate(
    model: Model,
    recording: Trajectory,
    *,
    markers: Sequence[str] | None = None,
    frames: tuple[int, int | None] = (0, None),
    substeps: int = 1,
    integrator: str = "euler",
    starts: int | Sequence[int] = DEFAULT_STARTS,
    threshold_mm: float = THRESHOLD_MM,
    horizon: int = DEFAULT_AHEAD,
    gait: bool = False,
    feet: Sequence[str] | None = None,
    up: Sequence[float] | None = None,
    body: Sequence[str] | None = None,
    origin: int | None = None,
    burn_in: int | None = None,
) -> Evaluation:
    """``model`` scored on frames ``START:STOP`` of ``recording`` (``markers``: one per
    particle, in order; default the model's). ``substeps`` and ``integrator``: the
    integration the model was fitted with; ``horizon``: the frames ahead of the multi-step
    comparison (1: one step only). ``gait``: score the free runs as a gait too
    (:mod:`activebonds.report.gait_runs`; ``feet``: particle names, ``up``: a vector, each
    found from the model or the recording when not given). ``body``: particle (or marker)
    names whose errors alone count in a second set of the free-run numbers. ``origin``: the
    recording's frame where the model's time is 0 (a clock drive and a moving anchor start
    there, an entrained drive's phase is tracked from there, the frames before the window
    filled as ``fit --validate`` fills them); default the window's first frame. ``burn_in``:
    N, also the free runs after an N-frame burn-in (:mod:`~activebonds.identify.judge.burn_in`),
    :data:`BURN_IN_HORIZON` frames long. Raises
    :class:`InputError` (one line) for markers or frames the recording does not have, or a
    ``body`` name the model does not have."""
    from ..identify.problem import select_data

    settings = _settings(markers, frames, substeps, integrator, horizon)
    start = settings.frames[0]
    if origin is not None and not 0 <= int(origin) <= start:
        raise InputError("--origin", f"must be a frame from 0 to the window's first, {start}")
    offset = 0 if origin is None else start - int(origin)
    data = select_data(model, recording, settings)
    before = _before(model, recording, settings, offset)
    run = {"substeps": substeps, "method": integrator, "offset": offset, "before": before}
    options = {"starts": starts, "threshold_mm": threshold_mm, "before": before}
    found = window_metrics(model, data, substeps, integrator, offset, **options)
    picked = _body(body, model.particle_names, data.markers)
    body_found = None
    if picked:  # the same runs, only these markers' errors counted
        body_found = window_metrics(
            model, data, substeps, integrator, offset, markers=picked, **options
        )
    gait_found = None
    if gait:
        where = {"feet": feet, "up": up, "offset": offset, "first_frame": start, "before": before}
        gait_found = gait_evaluation(model, data, substeps=substeps, integrator=integrator, **where)
    return Evaluation(
        model_name=model.name,
        source=str(recording.source or ""),
        frames=(int(start), int(start + data.n_frames)),
        markers=tuple(data.markers),
        substeps=int(substeps),
        integrator=integrator,
        model=found["model"],
        zero_force=found["zero_force"],
        particles=particle_scores(model, data, predict(model, data, **run)),
        comparisons=tuple(comparisons(model, data, horizon, **run)),
        gait=gait_found,
        holds=holds(model, data),
        body_markers=tuple(model.particle_names[i] for i in picked),
        body=body_found,
        burn_in=_burn_in(model, data, burn_in, substeps, integrator, offset, before),
    )


def _before(model: Model, recording: Trajectory, settings, offset: int):
    """The recorded frames from the model's time origin to the window (``offset`` of them,
    the model's markers; NaN where missing), along which an entrained drive's phase is
    tracked; None without any."""
    if offset <= 0:
        return None
    from ..identify.problem import select_data

    start, stop = settings.frames
    wider = settings.model_copy(update={"frames": (start - offset, stop)})
    return select_data(model, recording, wider).positions[:offset]


BURN_IN_HORIZON = 100  # frames of each free run after a burn-in, at most (the window's rest)


def _burn_in(model, data, frames, substeps, integrator, offset, before=None) -> BurnIn | None:
    """The free runs after a ``frames``-frame burn-in (None where not asked for); an
    InputError naming ``--burn-in`` where the window has no start with such a burn-in."""
    if frames is None:
        return None
    try:
        found = burn_in(
            model,
            data.positions,
            data.dt,
            int(frames),
            max(1, min(BURN_IN_HORIZON, data.n_frames - int(frames) - 1)),  # within the window
            substeps=substeps,
            method=integrator,
            offset=offset,
            before=before,
        )
    except ValueError as e:
        raise InputError("--burn-in", str(e)) from None
    return _with_template(found, model, data)


def _with_template(found: BurnIn, model: Model, data: Trajectory) -> BurnIn:
    """``found`` with the recording's mean gait as a predictor after the same burn-ins
    (:func:`~activebonds.report.gait.template_runs`), where the recording is rhythmic (its
    feet's heights have a period): found as it is otherwise."""
    from dataclasses import replace

    from . import gait as g
    from .gait_runs import recorded_gait

    rec = np.asarray(data.positions, np.float64)
    try:
        ref = recorded_gait(model, data)[0]
    except InputError:  # not rhythmic: no gait to play
        return found
    if not np.isfinite(ref.gait).all():
        return found
    runs = g.template_runs(rec, ref, found.starts, found.frames, found.horizon)
    curve, within = score(runs, targets(rec, found.starts, found.horizon), found.threshold_mm)
    return replace(found, template_mm=curve, template_within=within)


def _settings(markers, frames, substeps: int, integrator: str, horizon: int):
    """:func:`evaluate`'s options as a fit's settings (its markers, frames and integration);
    :class:`InputError` (one line, as the command line's options) for the first problem."""
    from ..identify.settings import FitSettings

    try:
        settings = FitSettings(
            markers=tuple(markers) if markers else None,
            frames=tuple(frames),
            substeps=substeps,
            integrator=integrator,
        )
    except ValidationError as e:  # as the command line's options: the first problem
        raise option_error(e) from None
    if int(horizon) < 1:
        raise InputError("--horizon", f"must be at least 1, got {horizon}")
    return settings


def particle_scores(model: Model, data: Trajectory, pred: Prediction) -> tuple[ParticleScore, ...]:
    """Per particle, the model's one-step and free-run RMS (``pred``, :func:`predict` along
    ``data``) beside zero force's on the same terms (its free run from the first free-run
    start)."""
    rec = np.asarray(data.positions, np.float64)
    first = start_frames(rec, 1)
    zero_one, zero_run = zero_force_predictions(rec, first[0] if first else rec.shape[0])
    zero_one_rms, zero_run_rms = rms_mm(zero_one, rec), rms_mm(zero_run, rec)
    return tuple(
        ParticleScore(
            particle=name,
            marker=marker,
            one_step=Score(float(pred.one_step_rms_mm[i]), float(zero_one_rms[i])),
            free_run=Score(
                float(pred.free_run_rms_mm[i]) if first else float("nan"), float(zero_run_rms[i])
            ),
        )
        for i, (name, marker) in enumerate(zip(model.particle_names, data.markers, strict=True))
    )


def _body(names: Sequence[str] | None, particles: Sequence[str], markers: Sequence[str]):
    """The particle indices of ``names`` (particle names, or the markers that follow them),
    in the model's order; InputError (``--body``) for a name neither holds."""
    if not names:
        return []
    out = []
    for name in names:
        if name in particles:
            out.append(list(particles).index(name))
        elif name in markers:
            out.append(list(markers).index(name))
        else:
            raise InputError(
                "--body", f"{name!r} is no particle of the model; they are {', '.join(particles)}"
            )
    return sorted(set(out))


def evaluate_files(model: str | Path, trajectory: str | Path, **options) -> Evaluation:
    """:func:`evaluate` of a model file on a trajectory file (any format ``read_trajectory``
    reads)."""
    from ..data import read_trajectory
    from ..model import load_model

    return evaluate(load_model(model), read_trajectory(trajectory), **options)
