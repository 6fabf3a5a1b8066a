"""Free run as a metric: one-step RMS, free-run RMS and frames until the free run is off.

One function, :func:`free_run_metrics`, gives the three numbers of a model along a recorded
window; :func:`zero_force_metrics` gives the same numbers of the zero-force (constant
velocity) predictor. The report, ``fit``'s summary and ``fit --validate`` all call them, so
the numbers agree everywhere.

* **One-step RMS** (mm): every frame predicted from the two recorded frames before it, as the
  fit cost predicts it (:func:`~activebonds.identify.judge.predictions.one_step`); the RMS over every
  (frame, marker) term whose target is recorded and whose two input frames are complete. For
  a run of horizon 1 it is the fit's own RMS error.
* **Free-run RMS** (mm): one free run from the first two complete consecutive frames
  (:func:`~activebonds.identify.judge.predictions.free_run`), never looking at the data again; the RMS
  over every later recorded (frame, marker). A run that went non-finite gives +inf.
* **Frames within the threshold**: free runs started from several frames ``s`` (the start
  frames, where frames ``s - 1`` and ``s`` are both complete; by default
  :data:`DEFAULT_STARTS` of them spread evenly over the first half of the window, so that
  every run has at least half of the window to go; each runs to the window's end). Each
  run's error at frame
  ``t > s`` is the **largest position error over the markers recorded at t** (the worst
  marker, not the RMS: a run is "off" as soon as one marker is). Its value is the number of
  frames ``t - s - 1`` before the first frame whose error exceeds ``threshold_mm`` (default
  :data:`THRESHOLD_MM`, 50 mm); a non-finite prediction exceeds any threshold; a frame with
  no recorded marker is no evidence either way and does not stop the count. A run that never
  exceeds it before the window ends is *censored*: its value is the frames it had (the true
  value is at least that), shown as ``>= N``. The summary is the median over the starts; it
  is a lower bound (censored) when any censored value is at or below it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from ...data import Trajectory
from ...model import Model
from .predictions import (
    before_window,
    free_run,
    one_step,
    tracked_phases,
    zero_force_predictions,
)
from .verdict import Record

THRESHOLD_MM = 50.0  # a free run is "off" once a marker is this far from its recording
DEFAULT_STARTS = 10  # free runs started, spread evenly over the window
MIN_STARTS = 5  # fewer possible start frames: too short a window to measure (--validate)
ERROR_MEASURE = "max over markers"  # what "off by more than the threshold" means


@dataclass(frozen=True)
class FreeRunMetrics(Record):
    """The three numbers of one predictor along one recorded window (frames are indices into
    that window; errors in mm); back from :meth:`to_dict` by :meth:`Record.from_dict` (raises
    KeyError, TypeError or ValueError if malformed)."""

    n_frames: int  # frames of the window
    threshold_mm: float
    one_step_rms_mm: float  # NaN if nothing can be predicted; +inf if a prediction failed
    free_run_rms_mm: float  # from the first start
    starts: tuple[int, ...]  # start frames s (frames s - 1 and s recorded, complete)
    frames_within: tuple[int, ...]  # per start: frames before the first one off (or all)
    censored: tuple[bool, ...]  # per start: never off before the window ended
    median_frames_within: float  # median over starts (NaN without a start)
    median_censored: bool  # the median is a lower bound

    def frames_text(self) -> str:
        """The median as people read it: ``37`` or ``>= 37`` (censored), ``—`` if none."""
        return censored_text(self.median_frames_within, self.median_censored)

    def to_dict(self) -> dict:
        """Plain JSON values (non-finite floats as the strings 'inf', '-inf' or 'nan')."""
        out = asdict(self)
        for key, value in out.items():
            if isinstance(value, float) and not np.isfinite(value):
                out[key] = str(value)
            elif isinstance(value, tuple):
                out[key] = list(value)
        out["error_measure"] = ERROR_MEASURE
        return out


def censored_text(value: float, censored: bool) -> str:
    if not np.isfinite(value):
        return "—"
    text = f"{value:g}"
    return f">= {text}" if censored else text


# ----------------------------------------------------------------------------- the counts


def max_error_mm(predicted: np.ndarray, recorded: np.ndarray) -> np.ndarray:
    """Per frame, the largest position error (mm) over the markers recorded there, [F]; NaN
    for a frame with no recorded marker, +inf where a recorded marker has no finite
    prediction."""
    p = np.asarray(predicted, np.float64)
    r = np.asarray(recorded, np.float64)
    known = np.isfinite(r).all(axis=-1)  # [F, P]
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.sqrt(np.sum((p - r) ** 2, axis=-1)) * 1000.0
    d = np.where(np.isfinite(d), d, np.inf)
    d = np.where(known, d, -np.inf)
    out = d.max(axis=1) if d.shape[1] else np.full(d.shape[0], -np.inf)
    return np.where(known.any(axis=1), out, np.nan)


def frames_within(
    predicted: np.ndarray, recorded: np.ndarray, threshold_mm: float = THRESHOLD_MM
) -> tuple[int, bool]:
    """Frames of a free run (``predicted``, aligned with ``recorded``: the frames after its
    start, [N, P, D]) before the first one off by more than ``threshold_mm`` (max over the
    recorded markers); ``(N, True)`` when none is (censored). Frames with no recorded marker
    do not stop the count."""
    err = max_error_mm(predicted, recorded)
    off = np.flatnonzero(err > threshold_mm)  # NaN compares False
    if off.size:
        return int(off[0]), False
    return int(err.shape[0]), True


def censored_median(values: Sequence[int], censored: Sequence[bool]) -> tuple[float, bool]:
    """Median of ``values`` and whether it is only a lower bound: some censored value at or
    below it could be larger and move it up."""
    v = np.asarray(values, np.float64)
    c = np.asarray(censored, bool)
    if v.size == 0:
        return float("nan"), False
    median = float(np.median(v))
    return median, bool((c & (v <= median)).any())


def start_frames(positions: np.ndarray, starts: int | Sequence[int] = DEFAULT_STARTS) -> list[int]:
    """Start frames of the free runs: frames ``s`` with ``s - 1`` and ``s`` complete and at
    least one frame after them. An int asks for that many, spread evenly over the possible
    ones in the first half of the window, ``s <= F // 2``, so that every run has at least
    half of the window to go (all of them if there are fewer); a sequence picks frames
    (those not possible are dropped)."""
    x = np.asarray(positions, np.float64)
    complete = np.isfinite(x).all(axis=(1, 2))
    ok = np.zeros(x.shape[0], bool)
    ok[1:-1] = complete[1:-1] & complete[:-2]
    possible = np.flatnonzero(ok)
    if not isinstance(starts, int | np.integer):
        return sorted({int(s) for s in starts if 0 <= int(s) < len(ok) and ok[int(s)]})
    possible = possible[possible <= x.shape[0] // 2]  # each run has half the window to go
    n = int(starts)
    if n <= 0 or possible.size == 0:
        return []
    if n >= possible.size:
        return possible.tolist()
    pick = np.unique(np.round(np.linspace(0, possible.size - 1, n)).astype(int))
    return possible[pick].tolist()


# ----------------------------------------------------------------------------- predictors


def _rms_terms(predicted: np.ndarray, recorded: np.ndarray, expected: np.ndarray) -> float:
    """RMS (mm) over the recorded (frame, marker) terms of the frames that ``expected`` says
    should be predicted; a missing or non-finite prediction there makes it +inf."""
    p = np.asarray(predicted, np.float64)[expected]
    r = np.asarray(recorded, np.float64)[expected]
    known = np.isfinite(r).all(axis=-1)
    if not known.any():
        return float("nan")
    with np.errstate(over="ignore", invalid="ignore"):
        err2 = np.sum((p - r) ** 2, axis=-1)[known]
    if not np.isfinite(err2).all():
        return float("inf")
    return float(np.sqrt(err2.mean()) * 1000.0)


def _metrics(
    recorded: np.ndarray,
    one: np.ndarray,
    run_from: Callable[[int], np.ndarray],
    starts: int | Sequence[int],
    threshold_mm: float,
    markers: Sequence[int] | None = None,
) -> FreeRunMetrics:
    """The three numbers from a one-step prediction [F, P, D] and ``run_from(s)``: a free run
    started at frame s (from frames s - 1 and s), predicting frames s + 1 ... F - 1.
    ``markers``: the indices of the markers whose errors count (default: every one); the
    predictions and the start frames are those of every marker (a run starts where all are
    recorded)."""
    rec = np.asarray(recorded, np.float64)
    n = rec.shape[0]
    complete = np.isfinite(rec).all(axis=(1, 2))
    expected = np.zeros(n, bool)
    expected[2:] = complete[1:-1] & complete[:-2]
    chosen = start_frames(rec, starts)
    first = start_frames(rec, 1)
    if markers is not None:
        pick = list(markers)
        rec, one = rec[:, pick], np.asarray(one)[:, pick]
        whole = run_from
        run_from = lambda s: whole(s)[:, pick]  # noqa: E731
    one_rms = _rms_terms(one, rec, expected)
    runs = {s: run_from(s) for s in sorted(set(chosen) | set(first))}
    free_rms = float("nan")
    if first:
        s = first[0]
        free_rms = _rms_terms(runs[s], rec[s + 1 :], np.ones(n - s - 1, bool))
    counts = [frames_within(runs[s], rec[s + 1 :], threshold_mm) for s in chosen]
    values = [c[0] for c in counts]
    cens = [c[1] for c in counts]
    median, median_cens = censored_median(values, cens)
    return FreeRunMetrics(
        n_frames=n,
        threshold_mm=float(threshold_mm),
        one_step_rms_mm=one_rms,
        free_run_rms_mm=free_rms,
        starts=tuple(chosen),
        frames_within=tuple(values),
        censored=tuple(cens),
        median_frames_within=median,
        median_censored=median_cens,
    )


def free_run_metrics(
    model: Model,
    trajectory: Trajectory,
    *,
    substeps: int = 1,
    method: str = "euler",
    starts: int | Sequence[int] = DEFAULT_STARTS,
    threshold_mm: float = THRESHOLD_MM,
    offset: int = 0,
    markers: Sequence[int] | None = None,
    before: np.ndarray | None = None,
) -> FreeRunMetrics:
    """One-step RMS, free-run RMS and frames within ``threshold_mm`` of ``model`` along
    ``trajectory`` (markers in the model's particle order; ``substeps`` and ``method``: the
    run's integration, as in its settings). See the module's docstring for the definitions.
    ``markers``: the indices of the markers whose errors count (e.g. the body's, not the
    feet's; default: every one), the model's runs those of all.

    ``offset``: frames from the model's time origin (the fitted window's first frame, where
    predictions take time 0) to ``trajectory``'s first frame, e.g. ``300`` for frames 300:400
    validating a fit of 0:300; only a model whose forces depend on time sees it. ``before``:
    the recorded frames between the origin and ``trajectory`` (an entrained drive's phase is
    tracked along them, :func:`~.predictions.before_window`)."""
    if trajectory.n_markers != model.topology.n_particles:
        raise ValueError(
            f"{trajectory.n_markers} markers for a model of {model.topology.n_particles} particles"
        )
    rec = np.asarray(trajectory.positions, np.float64)
    dt = trajectory.dt
    n = rec.shape[0]
    pad = max(int(offset), 0)
    # the frames before the trajectory (recorded or unknown) put its frames at their time
    # from the origin
    timed = before_window(rec, pad, before)
    one = one_step(model, timed, dt, substeps, method)[pad:]
    phases = tracked_phases(model, timed, dt, substeps)  # an entrained drive's, else None

    def run_from(s: int) -> np.ndarray:
        # always n - 2 steps (one compiled program for every start), of which frames
        # s + 1 ... n - 1 are kept
        return free_run_from(model, rec, dt, s, n - 2, substeps, method, offset, phases)[
            : n - s - 1
        ]

    return _metrics(rec, one, run_from, starts, threshold_mm, markers)


def free_run_from(
    model: Model,
    positions: np.ndarray,
    dt: float,
    start: int,
    n_steps: int,
    substeps: int = 1,
    method: str = "euler",
    offset: int = 0,
    phases: np.ndarray | None = None,
    before: np.ndarray | None = None,
) -> np.ndarray:
    """The model's free run from the recorded frames ``start - 1`` and ``start`` of
    ``positions`` [F, P, D] (complete), at their own time (``offset``: see
    :func:`free_run_metrics`): the ``n_steps`` frames after ``start`` [n_steps, P, D], which
    may run past the recording's end; NaN once the run went non-finite. Runs of the same
    ``n_steps`` share one compiled program, whatever their start. An entrained drive starts
    at ``phases`` [offset + frames] (default: tracked along ``positions``)."""
    x = np.asarray(positions, np.float64)
    pad = max(int(offset), 0)
    s = pad + int(start)
    if phases is None:  # an entrained drive's phase, tracked along the whole recording
        phases = tracked_phases(model, before_window(x, pad, before), dt, substeps)
    # the recording hidden but for the start pair: the run starts there, at its time
    hidden = np.full((s + 1, *x.shape[1:]), np.nan)
    hidden[s - 1 :] = x[start - 1 : start + 1]
    xs, _ = free_run(model, hidden, dt, s + 1 + int(n_steps), substeps, method, phases)
    return xs[s + 1 :]


def zero_force_metrics(
    trajectory: Trajectory,
    *,
    starts: int | Sequence[int] = DEFAULT_STARTS,
    threshold_mm: float = THRESHOLD_MM,
    markers: Sequence[int] | None = None,
) -> FreeRunMetrics:
    """The same numbers for the zero-force (constant-velocity) predictor: one step
    ``x_t = 2 x_{t-1} - x_{t-2}``, free run ``x_t = x_s + (t - s) (x_s - x_{s-1})``
    (``markers``: as :func:`free_run_metrics`'s)."""
    rec = np.asarray(trajectory.positions, np.float64)
    one = zero_force_predictions(rec, 1)[0]

    def run_from(s: int) -> np.ndarray:
        return zero_force_predictions(rec, s)[1][s + 1 :]

    return _metrics(rec, one, run_from, starts, threshold_mm, markers)


def window_metrics(
    model: Model,
    trajectory: Trajectory,
    substeps: int,
    method: str,
    offset: int = 0,
    before: np.ndarray | None = None,
    **options,
) -> dict[str, FreeRunMetrics]:
    """``{"model": ..., "zero_force": ...}`` on one window (``offset``: see
    :func:`free_run_metrics`; ``options``: starts, threshold_mm)."""
    return {
        "model": free_run_metrics(
            model,
            trajectory,
            substeps=substeps,
            method=method,
            offset=offset,
            before=before,
            **options,
        ),
        "zero_force": zero_force_metrics(trajectory, **options),
    }


# ----------------------------------------------------------------------------- validation

MIN_VALIDATION_FRAMES = 10


def validation_data(
    model: Model, recording: Trajectory, settings, frames: tuple[int, int | None]
) -> Trajectory:
    """Frames ``START:STOP`` of ``recording`` (the model's markers, as the fit selects them)
    for validation. Raises :class:`InputError` (``--validate``) for a window out of range,
    overlapping the fitted frames (``settings.frames``), shorter than
    :data:`MIN_VALIDATION_FRAMES` or with fewer than :data:`MIN_STARTS` possible starts."""
    from ...errors import InputError
    from ..problem import select_data

    n = recording.n_frames
    start, stop = frames
    stop = n if stop is None else stop
    if start < 0 or stop > n or start >= stop:
        raise InputError(
            "--validate", f"frames {start}:{stop} are out of range: the recording has {n} frames"
        )
    fit_start, fit_stop = settings.frames
    fit_stop = n if fit_stop is None else min(fit_stop, n)
    if start < fit_stop and fit_start < stop:
        raise InputError(
            "--validate",
            f"frames {start}:{stop} overlap the fitted frames {fit_start}:{fit_stop}; "
            "validate on frames the fit does not use",
        )
    if stop - start < MIN_VALIDATION_FRAMES:
        raise InputError(
            "--validate",
            f"frames {start}:{stop} hold {stop - start} frames; at least "
            f"{MIN_VALIDATION_FRAMES} needed",
        )
    data = select_data(model, recording, settings.model_copy(update={"frames": (start, stop)}))
    possible = len(start_frames(data.positions, stop - start))
    if possible < MIN_STARTS:
        raise InputError(
            "--validate",
            f"frames {start}:{stop} allow {possible} free-run starts (two complete frames in "
            f"the window's first half); at least {MIN_STARTS} needed",
        )
    return data


def validation_record(
    model: Model, data: Trajectory, settings, frames: tuple[int, int], **options
) -> dict:
    """What RUN/validation.json holds: the frames, the model's and the zero-force
    predictor's metrics on them (:func:`window_metrics`) and their comparisons one step and
    :data:`~activebonds.identify.judge.ahead.DEFAULT_AHEAD` frames ahead, overall and per marker
    (``judged``, :mod:`activebonds.identify.judge.ahead`)."""
    # time runs on from the fitted window (a window before it starts at time 0)
    offset = max(int(frames[0]) - int(settings.frames[0]), 0)
    found = window_metrics(
        model, data, settings.substeps, settings.integrator, offset=offset, **options
    )
    from .ahead import DEFAULT_AHEAD, comparisons

    judged = comparisons(
        model,
        data,
        DEFAULT_AHEAD,
        substeps=settings.substeps,
        method=settings.integrator,
        offset=offset,
    )
    return {
        "frames": [int(frames[0]), int(frames[1])],
        "source": data.source,
        "time_offset_frames": offset,
        **{name: m.to_dict() for name, m in found.items()},
        "judged": [c.to_dict() for c in judged],
    }


def read_validation(record: dict) -> tuple[tuple[int, int], dict[str, FreeRunMetrics]]:
    """Frames and metrics back from :func:`validation_record`'s dict."""
    frames = (int(record["frames"][0]), int(record["frames"][1]))
    return frames, {k: FreeRunMetrics.from_dict(record[k]) for k in ("model", "zero_force")}
