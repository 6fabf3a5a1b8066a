"""Is a free run a gait like the recording's, whatever its phase? Four numbers, NumPy only.

Free runs of a predictor start at :data:`STARTS` frames of a recorded window (spread over it)
and run :data:`STRIDES` strides each (the stride: the recording's dominant period, below),
past the window's end if need be: nothing is compared frame by frame, so a run whose phase
drifts from the recording's loses nothing. The feet (hooves) are named markers; heights are
along the vertical axis (the up unit vector). Against the recording, each run gives:

(i) **period**: the dominant period (frames) of the feet's heights, from their
    autocorrelation (:func:`dominant_period`: the Pearson correlation of the heights with
    themselves ``k`` frames later, averaged over the feet; its first peak after the first
    zero crossing that reaches 0.9 of the highest, refined by a parabola to a fraction of a
    frame). The summary is the median over runs, against the recording's own period;
(ii) **excursion**: each foot's vertical peak-to-peak (mm), the median over consecutive
    windows of one (recorded) stride of max - min (:func:`excursions`); per foot, the median
    over runs, as a ratio to the recording's;
(iii) **body distance**: the largest distance (mm) of any body marker (every marker that is
    not a foot) at any frame of the run from its mean position over the recorded window: a
    run that drifts away or collapses shows it. The summary is the largest over runs, beside
    the recording's own wander over spans as long as a run (:func:`own_wander_mm`): a body on
    a treadmill drifts too;
(iv) **cycle RMS**: the run cut into cycles of its own period (the recording's when it has
    none), each resampled at :data:`PHASE_BINS` phases and averaged (the run's cycle
    average); after the best circular phase shift, its RMS (mm, all markers, 3-D distance)
    against the recording's mean gait (:func:`mean_gait`: the recorded cycles, each shifted to
    its best phase, averaged). Beside it the recording's own cycle-to-cycle spread: the RMS of
    its aligned cycles against the mean gait. The summary is the median over runs. Beside
    it, for information (no target), the same with each marker's mean position over the
    cycle removed from both (the cycle's shape, wherever the body is: a body that stands a
    little off its recorded place shows in (iii), not here).

A run that goes non-finite scores +inf on all four (a failure, not a gap). Each summary
passes or fails against the thresholds below: (i) and (ii) relative to the recording's period
and excursions, (iii) and (iv) to the recording's own wander and cycle-to-cycle spread (issue
28's fixed 100 mm and 50 mm were failed by the bundled recordings themselves: the trot's body
wanders 109 mm, the walk's own cycles are 61 mm apart).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from ..data.period import dominant_period
from ..identify.judge.predictions import constant_velocity
from ..nanstats import nanmean

STRIDES = 5  # strides of each free run
STARTS = 10  # free runs, from start frames spread over the window
PHASE_BINS = 200  # phases per cycle: a shift resolution of 1/200 of a stride
PERIOD_TOLERANCE = 0.03  # (i) within 3 % of the recording's period
EXCURSION_TOLERANCE = 0.25  # (ii) every foot within 25 % of its recorded excursion
# (iii) the body's wander within this factor of the recording's own over the same spans, and
# (iv) the cycle average within this factor of the recording's cycle-to-cycle spread ...
OWN_FACTOR = 1.25
# ... or within this many mm of the mean gait, where the recording's own is less (a
# noise-free recording, whose cycles are its mean gait: the resampling's error)
OWN_FLOOR_MM = 5.0


# ----------------------------------------------------------------------------- signals


def vertical(positions: np.ndarray, up: Sequence[float]) -> np.ndarray:
    """Heights along the unit vector ``up`` (m), [..., P]."""
    n = np.asarray(up, np.float64)
    return np.asarray(positions, np.float64) @ (n / np.linalg.norm(n))


def lowest_markers(positions: np.ndarray, up: Sequence[float], share: float = 0.25) -> list[int]:
    """The markers whose mean height lies in the lowest ``share`` of the range of the
    markers' mean heights (the feet of a standing or walking body)."""
    h = nanmean(vertical(positions, up), axis=0)
    lo, hi = np.nanmin(h), np.nanmax(h)
    return [int(i) for i in np.flatnonzero(h <= lo + share * (hi - lo))]


def excursions(heights: np.ndarray, stride: float) -> np.ndarray:
    """Each column's peak-to-peak (same unit as ``heights`` [F, H]): the median over
    consecutive windows of ``round(stride)`` frames of max - min (the whole signal when it is
    shorter than one window, or ``stride`` is not finite); NaN frames left out (a gap in a
    recording), NaN for a column with none."""
    h = np.asarray(heights, np.float64)
    if h.ndim == 1:
        h = h[:, None]
    w = max(int(round(stride)), 2) if np.isfinite(stride) else h.shape[0]
    n = max(h.shape[0] // w, 1)
    w = min(w, h.shape[0])
    blocks = h[: n * w].reshape(n, w, h.shape[1])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN window: NaN
        return np.nanmedian(np.nanmax(blocks, axis=1) - np.nanmin(blocks, axis=1), axis=0)


# ----------------------------------------------------------------------------- cycles


def cycles(positions: np.ndarray, period: float, bins: int = PHASE_BINS) -> np.ndarray:
    """The complete cycles of ``positions`` [F, P, D] of ``period`` frames from frame 0, each
    resampled (linearly in time) at ``bins`` phases, [K, bins, P, D] (K = 0 when shorter than
    one period)."""
    x = np.asarray(positions, np.float64)
    k = int(np.floor((x.shape[0] - 1) / period)) if np.isfinite(period) and period > 0 else 0
    if k == 0:
        return np.zeros((0, bins, *x.shape[1:]))
    t = (np.arange(k)[:, None] + np.arange(bins)[None, :] / bins) * period  # [K, bins]
    i = np.minimum(np.floor(t).astype(int), x.shape[0] - 2)
    f = (t - i)[..., None, None]
    return x[i] * (1.0 - f) + x[i + 1] * f


def best_shift(cycle: np.ndarray, template: np.ndarray) -> tuple[int, float]:
    """The circular shift ``s`` (bins) with ``np.roll(cycle, s, axis=0)`` closest to
    ``template`` (both [bins, P, D]) and its RMS distance (mm, over the bins and markers
    known in both) at the best fractional shift near it (the lowest value of the parabola
    through the squared distances of ``s - 1``, ``s``, ``s + 1``)."""
    m = cycle.shape[0]
    index = (np.arange(m)[None, :] - np.arange(m)[:, None]) % m  # [shift, bin]
    d2 = np.sum((cycle[index] - template[None]) ** 2, axis=-1)  # [shift, bins, P]
    with np.errstate(invalid="ignore"):
        mean = nanmean(d2.reshape(m, -1), axis=1)
    if not np.isfinite(mean).any():
        return 0, float("inf")
    s = int(np.nanargmin(mean))
    a, b, c = mean[s - 1], mean[s], mean[(s + 1) % m]
    curve = a - 2.0 * b + c
    # the parabola's lowest value between the bins: the best fractional shift's distance
    best = b - (a - c) ** 2 / (8.0 * curve) if curve > 0 else b
    return s, float(np.sqrt(max(best, 0.0)) * 1000.0)


def mean_gait(
    positions: np.ndarray, period: float, rounds: int = 3
) -> tuple[np.ndarray, float, float]:
    """The recording's mean gait [bins, P, D] and its cycle-to-cycle spread (mm), with each
    marker's mean position over each cycle and over the mean gait kept and removed: the
    cycles (:func:`cycles`) are averaged, each is shifted to its best phase against the
    average and they are averaged again (``rounds`` times); the spread is the RMS of the
    shifted cycles against the mean gait (NaN with fewer than two cycles)."""
    c = cycles(positions, period)
    nan = float("nan")
    if c.shape[0] == 0:
        return np.full((PHASE_BINS, *np.shape(positions)[1:]), np.nan), nan, nan
    template = nanmean(c, axis=0)
    for _ in range(rounds):
        c = np.stack([np.roll(ci, best_shift(ci, template)[0], axis=0) for ci in c])
        template = nanmean(c, axis=0)
    if c.shape[0] < 2:
        return template, nan, nan
    shape = (c - nanmean(c, axis=1, keepdims=True)) - (template - nanmean(template, 0))
    with np.errstate(invalid="ignore"):
        spread = np.sqrt(nanmean(np.sum((c - template) ** 2, axis=-1))) * 1000.0
        spread_shape = np.sqrt(nanmean(np.sum(shape**2, axis=-1))) * 1000.0
    return template, float(spread), float(spread_shape)


def cycle_average(positions: np.ndarray, period: float) -> np.ndarray:
    """The mean of the cycles of ``positions`` [F, P, D] of ``period`` frames,
    [bins, P, D] (NaN when shorter than one period)."""
    c = cycles(positions, period)
    if c.shape[0] == 0:
        return np.full((PHASE_BINS, *np.shape(positions)[1:]), np.nan)
    return c.mean(axis=0)


# ----------------------------------------------------------------------------- scores


@dataclass(frozen=True)
class GaitFeatures:
    """What a recorded window says of its gait (heights along ``up``; mm unless said)."""

    up: tuple[float, ...]
    feet: tuple[int, ...]  # marker indices
    body: tuple[int, ...]
    period_frames: float
    excursion_mm: tuple[float, ...]  # per foot
    body_distance_mm: float  # the recording's own largest distance from its mean positions
    own_wander_mm: float  # ... and its largest over spans as long as a free run (stride_frames)
    spread_mm: float  # cycle-to-cycle RMS against the mean gait
    spread_shape_mm: float  # the same, each marker's mean over each cycle removed
    mean_positions: np.ndarray  # [P, D] m
    gait: np.ndarray  # [bins, P, D] m, the mean gait


def features(
    positions: np.ndarray, up: Sequence[float], feet: Sequence[int], period: float | None = None
) -> GaitFeatures:
    """The gait of a recorded window [F, P, D] (``period``: frames, default its dominant
    period)."""
    x = np.asarray(positions, np.float64)
    feet = tuple(int(i) for i in feet)
    body = tuple(i for i in range(x.shape[1]) if i not in feet)
    h = vertical(x, up)[:, list(feet)]
    t = dominant_period(h) if period is None else float(period)
    mean = nanmean(x, axis=0)
    gait, spread, spread_shape = mean_gait(x, t)
    return GaitFeatures(
        up=tuple(float(u) for u in up),
        feet=feet,
        body=body,
        period_frames=t,
        excursion_mm=tuple(float(e) * 1000.0 for e in excursions(h, t)),
        body_distance_mm=_distance_mm(x, mean, body),
        own_wander_mm=own_wander_mm(
            x, mean, body, int(np.ceil(STRIDES * t)) if np.isfinite(t) else 0
        ),
        spread_mm=spread,
        spread_shape_mm=spread_shape,
        mean_positions=mean,
        gait=gait,
    )


def own_wander_mm(x: np.ndarray, mean: np.ndarray, body: Sequence[int], span: int) -> float:
    """The recording's own (iii): the largest body distance from ``mean`` within any span of
    ``span`` frames (a free run's length), spans a quarter of one apart; the whole window's
    where it is shorter than a span (or ``span`` is 0)."""
    n = x.shape[0]
    if span <= 0 or span >= n:
        return _distance_mm(x, mean, body)
    step = max(1, span // 4)
    starts = list(range(0, n - span + 1, step))
    if starts[-1] != n - span:
        starts.append(n - span)
    return max(_distance_mm(x[a : a + span], mean, body) for a in starts)


def _distance_mm(x: np.ndarray, mean: np.ndarray, body: Sequence[int]) -> float:
    if not body:
        return float("nan")
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.sqrt(np.sum((x[:, list(body)] - mean[list(body)]) ** 2, axis=-1))
    if np.isinf(d).any():
        return float("inf")
    return float(np.nanmax(d) * 1000.0) if np.isfinite(d).any() else float("nan")


@dataclass(frozen=True)
class RunScore:
    """The four numbers of one free run [N, P, D] (frames after its start)."""

    period_frames: float  # +inf for a run that went non-finite, NaN: no period
    excursion_mm: tuple[float, ...]  # per foot
    body_distance_mm: float
    cycle_rms_mm: float
    cycle_shape_rms_mm: float  # the same, each marker's mean over the cycle removed


def score_run(run: np.ndarray, ref: GaitFeatures) -> RunScore:
    """(i)-(iv) of one run against the recording's :func:`features`."""
    x = np.asarray(run, np.float64)
    n_feet = len(ref.feet)
    if not np.isfinite(x).all():
        inf = float("inf")
        return RunScore(inf, (inf,) * n_feet, inf, inf, inf)
    h = vertical(x, ref.up)[:, list(ref.feet)]
    t = dominant_period(h)
    ex = excursions(h, ref.period_frames) * 1000.0
    dist = _distance_mm(x, ref.mean_positions, ref.body)
    avg = cycle_average(x, t if np.isfinite(t) else ref.period_frames)
    if np.isfinite(avg).all():
        rms = best_shift(avg, ref.gait)[1]
        shape = best_shift(avg - avg.mean(axis=0), ref.gait - nanmean(ref.gait, axis=0))[1]
    else:
        rms = shape = float("inf")
    return RunScore(t, tuple(float(e) for e in ex), dist, rms, shape)


@dataclass(frozen=True)
class GaitScore:
    """A predictor's runs summarised, each number with its pass (issue 28's thresholds)."""

    period_frames: float  # median over runs (a run without a period counts as +inf)
    period_error: float  # |period / recorded - 1|
    excursion_ratio: tuple[float, ...]  # per foot: median over runs / recorded
    body_distance_mm: float  # largest over runs
    cycle_rms_mm: float  # median over runs
    cycle_shape_rms_mm: float  # median over runs (information: no target)
    runs: tuple[RunScore, ...]
    own_wander_mm: float = float("nan")  # the recording's (iii) over spans of a run's length
    own_spread_mm: float = float("nan")  # the recording's cycle-to-cycle spread ((iv)'s own)

    @property
    def period_ok(self) -> bool:
        return bool(self.period_error <= PERIOD_TOLERANCE)

    @property
    def excursion_ok(self) -> bool:
        r = np.asarray(self.excursion_ratio, np.float64)
        return bool(r.size and (np.abs(r - 1.0) <= EXCURSION_TOLERANCE).all())

    @property
    def body_limit_mm(self) -> float:
        """(iii)'s target: :data:`OWN_FACTOR` times the recording's own wander."""
        return own_limit(self.own_wander_mm)

    @property
    def cycle_limit_mm(self) -> float:
        """(iv)'s target: :data:`OWN_FACTOR` times the recording's own spread."""
        return own_limit(self.own_spread_mm)

    @property
    def body_ok(self) -> bool:
        return bool(self.body_distance_mm <= self.body_limit_mm)

    @property
    def cycle_ok(self) -> bool:
        return bool(self.cycle_rms_mm <= self.cycle_limit_mm)

    @property
    def passes(self) -> dict[str, bool]:
        return {
            "period": self.period_ok,
            "excursion": self.excursion_ok,
            "body": self.body_ok,
            "cycle": self.cycle_ok,
        }

    def to_dict(self) -> dict:
        out = asdict(self)
        out["passes"] = self.passes
        out["body_limit_mm"], out["cycle_limit_mm"] = self.body_limit_mm, self.cycle_limit_mm
        return plain(out)


def own_limit(own_mm: float) -> float:
    """A target relative to the recording's own value: :data:`OWN_FACTOR` times it, at least
    :data:`OWN_FLOOR_MM`."""
    return max(OWN_FACTOR * own_mm, OWN_FLOOR_MM) if np.isfinite(own_mm) else OWN_FLOOR_MM


def summarise(scores: Sequence[RunScore], ref: GaitFeatures) -> GaitScore:
    """The runs' scores against the recording's features."""
    if not scores:
        nan = float("nan")
        own = (ref.own_wander_mm, ref.spread_mm)
        return GaitScore(nan, nan, (nan,) * len(ref.feet), nan, nan, nan, (), *own)
    periods = np.array([s.period_frames for s in scores], np.float64)
    period = float(np.median(np.where(np.isnan(periods), np.inf, periods)))
    with np.errstate(invalid="ignore"):
        error = abs(period / ref.period_frames - 1.0) if np.isfinite(period) else float("inf")
        ex = np.median(np.array([s.excursion_mm for s in scores], np.float64), axis=0)
        ratio = ex / np.asarray(ref.excursion_mm, np.float64)
    return GaitScore(
        period_frames=period,
        period_error=float(error),
        excursion_ratio=tuple(float(r) for r in ratio),
        body_distance_mm=float(max(s.body_distance_mm for s in scores)),
        cycle_rms_mm=float(np.median([s.cycle_rms_mm for s in scores])),
        cycle_shape_rms_mm=float(np.median([s.cycle_shape_rms_mm for s in scores])),
        runs=tuple(scores),
        own_wander_mm=ref.own_wander_mm,
        own_spread_mm=ref.spread_mm,
    )


def gait_starts(positions: np.ndarray, n: int = STARTS) -> list[int]:
    """``n`` start frames ``s`` spread evenly over the window, with frames ``s - 1`` and
    ``s`` complete (all of them if there are fewer)."""
    x = np.asarray(positions, np.float64)
    complete = np.isfinite(x).all(axis=(1, 2))
    ok = np.flatnonzero(complete[1:] & complete[:-1]) + 1
    if ok.size <= n:
        return ok.tolist()
    return ok[np.unique(np.round(np.linspace(0, ok.size - 1, n)).astype(int))].tolist()


def stride_frames(ref: GaitFeatures, strides: int = STRIDES) -> int:
    """Frames of a free run: ``strides`` recorded periods (rounded up)."""
    return int(np.ceil(strides * ref.period_frames))


def template_runs(
    positions: np.ndarray, ref: GaitFeatures, starts: Sequence[int], burn: int, n: int
) -> np.ndarray:
    """The recording's mean gait played as a predictor after a burn-in: for each start s, the
    phase (of :data:`PHASE_BINS`) and the body's offset (the mean over the burn-in frames
    s - ``burn`` ... s and the markers) that best fit those recorded frames, then the mean
    gait at that phase and offset ``n`` frames on, [S, n, P, D]. The baseline a gait model's
    free runs after a burn-in must beat (the nonlinear system-identification benchmarks'
    convention, with the recording's own cycle for a model)."""
    x = np.asarray(positions, np.float64)
    step = PHASE_BINS / ref.period_frames  # phase bins per frame
    phases = np.arange(PHASE_BINS, dtype=np.float64)

    def played(start_phase: np.ndarray, k: np.ndarray) -> np.ndarray:  # [..., K, P, D]
        p = (start_phase[..., None] + k * step) % PHASE_BINS
        i = np.floor(p).astype(int)
        f = (p - i)[..., None, None]
        return ref.gait[i] * (1 - f) + ref.gait[(i + 1) % PHASE_BINS] * f

    out = []
    k_burn = np.arange(burn + 1, dtype=np.float64)
    k_ahead = np.arange(burn + 1, burn + 1 + n, dtype=np.float64)
    cands = played(phases, k_burn)  # [bins, burn + 1, P, D]
    for s in starts:
        window = x[s - burn : s + 1]  # [burn + 1, P, D]
        offset = nanmean(window[None] - cands, axis=(1, 2))  # [bins, D]
        err = nanmean(np.sum((window[None] - cands - offset[:, None, None]) ** 2, -1), (1, 2))
        best = int(np.nanargmin(err))
        out.append(played(phases[best : best + 1], k_ahead)[0] + offset[best])
    return np.stack(out)


def constant_velocity_runs(positions: np.ndarray, starts: Sequence[int], n: int) -> np.ndarray:
    """The zero-force predictor's free runs: ``x_s + k (x_s - x_{s-1})`` for k = 1 .. n from
    each start, [S, n, P, D]."""
    x = np.asarray(positions, np.float64)
    s = np.asarray(starts, int)
    k = np.arange(1, n + 1, dtype=np.float64)[None, :, None, None]
    return constant_velocity(x[s][:, None], (x[s] - x[s - 1])[:, None], k)


def plain(value):
    """JSON values: tuples as lists, non-finite floats as 'inf', '-inf' or 'nan'."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, float | np.floating):
        return float(value) if np.isfinite(value) else str(float(value))
    return value
