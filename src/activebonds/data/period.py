"""Does a recording repeat itself? Its dominant period, from the autocorrelation, NumPy only.

:func:`dominant_period` finds the period (frames) of signals [F, H] (one column each: a gait's
feet heights, :mod:`activebonds.report.gait`): the first peak of their mean autocorrelation
after its first zero crossing that reaches :data:`PEAK_SHARE` of the highest, refined by a
parabola; none (NaN) when no peak reaches :data:`MIN_PEAK`. :func:`recording_period` asks it
of a recording's markers: their heights along the vertical when it is known, else every
coordinate, each with its straight-line trend removed (a body walking on, or sliding, repeats
nothing in its position along the way, but its gait bobs up and down each stride). A walking,
trotting or swinging body has a period; a thrown body that lands and comes to rest has none.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

PEAK_SHARE = 0.9  # the period's peak: the first reaching this share of the highest peak
MIN_PEAK = 0.3  # a correlation below this at every peak: no period


def autocorrelation(heights: np.ndarray, max_lag: int) -> np.ndarray:
    """Per lag ``k = 0 .. max_lag``, the Pearson correlation of each column of ``heights``
    [F, H] with itself ``k`` frames later, averaged over the columns that vary (NaN frames
    left out), [max_lag + 1]; NaN where nothing is defined. The columns of a lag at once."""
    h = np.asarray(heights, np.float64)
    out = np.full(max_lag + 1, np.nan)
    for k in range(max_lag + 1):
        a, b = h[: h.shape[0] - k], h[k:]
        ok = np.isfinite(a) & np.isfinite(b)  # [F - k, H]
        n = ok.sum(axis=0)
        use = n >= 3
        if not use.any():
            continue
        count = np.maximum(n, 1)
        x = np.where(ok, a - np.where(ok, a, 0.0).sum(axis=0) / count, 0.0)
        y = np.where(ok, b - np.where(ok, b, 0.0).sum(axis=0) / count, 0.0)
        den = np.sqrt((x * x).sum(axis=0) * (y * y).sum(axis=0))
        use &= den > 0
        if use.any():
            out[k] = float(np.mean((x * y).sum(axis=0)[use] / den[use]))
    return out


def dominant_period(heights: np.ndarray, max_lag: int | None = None) -> float:
    """The dominant period (frames) of ``heights`` [F, H] (one column per foot): the first
    peak of :func:`autocorrelation` after its first zero crossing that reaches
    :data:`PEAK_SHARE` of the highest peak, refined by a parabola through it and its
    neighbours. ``max_lag``: the longest lag looked at (default half the frames, so that
    every lag has half the signal to correlate). NaN when there is no such peak, or the
    highest is below :data:`MIN_PEAK`, or the heights are not finite."""
    h = np.asarray(heights, np.float64)
    if h.ndim == 1:
        h = h[:, None]
    if np.isinf(h).any() or not np.isfinite(h).any():
        return float("nan")
    n = h.shape[0]
    lag = n // 2 if max_lag is None else min(int(max_lag), n - 3)
    if lag < 3:
        return float("nan")
    r = autocorrelation(h, lag)
    below = np.flatnonzero(r < 0)
    if below.size == 0:
        return float("nan")
    k = np.arange(int(below[0]) + 1, lag)
    peaks = k[(r[k] >= r[k - 1]) & (r[k] > r[k + 1])]
    if peaks.size == 0 or np.nanmax(r[peaks]) < MIN_PEAK:
        return float("nan")
    p = int(peaks[np.flatnonzero(r[peaks] >= PEAK_SHARE * np.nanmax(r[peaks]))[0]])
    a, b, c = r[p - 1], r[p], r[p + 1]
    curve = a - 2.0 * b + c
    shift = 0.5 * (a - c) / curve if curve < 0 else 0.0
    return float(p + np.clip(shift, -0.5, 0.5))


def detrended(
    positions: np.ndarray, mask: np.ndarray | None = None, up: Sequence[float] | None = None
) -> np.ndarray:
    """The columns whose period :func:`recording_period` finds [F, H]: a recording's marker
    heights along ``up`` (any non-zero vector) when given, else every coordinate, each with its
    least-squares straight line in time removed (NaN where not recorded)."""
    x = np.asarray(positions, np.float64)
    if mask is not None:
        x = np.where(np.asarray(mask, bool)[..., None], x, np.nan)
    if up is not None and np.linalg.norm(up) > 0:
        n = np.asarray(up, np.float64)
        columns = x @ (n / np.linalg.norm(n))
    else:
        columns = x.reshape(x.shape[0], -1)
    t = np.arange(x.shape[0], dtype=np.float64)
    out = np.full_like(columns, np.nan)
    for j in range(columns.shape[1]):
        ok = np.isfinite(columns[:, j])
        if ok.sum() < 3:
            continue
        slope, intercept = np.polyfit(t[ok], columns[ok, j], 1)
        out[:, j] = columns[:, j] - (slope * t + intercept)
    return out


def recording_period(
    positions: np.ndarray, mask: np.ndarray | None = None, up: Sequence[float] | None = None
) -> float:
    """The dominant period (frames, :func:`dominant_period`) of a recording's markers
    ``positions`` [F, P, D] (``mask`` [F, P]: the recorded ones): of their heights along
    ``up`` (any non-zero vector) when given, else of every coordinate; each column's
    least-squares straight line in time removed first (:func:`detrended`). NaN: the recording
    repeats nothing (or is too short to tell: fewer than two periods)."""
    x = np.asarray(positions)
    if x.ndim != 3 or x.shape[0] < 8:
        return float("nan")
    out = detrended(x, mask, up)
    if not np.isfinite(out).any():
        return float("nan")
    return dominant_period(out)


def peak_height(columns: np.ndarray, period: float) -> float:
    """The mean autocorrelation of ``columns`` [F, H] at a lag of ``period`` frames, linear
    between the whole lags either side: how alike one period and the next are (1: a perfect
    repeat; :data:`MIN_PEAK` the least :func:`dominant_period` calls a period). NaN for a
    period that is not finite."""
    if not np.isfinite(period):
        return float("nan")
    r = autocorrelation(columns, int(np.ceil(period)))
    k = int(np.floor(period))
    w = period - k
    return float((1.0 - w) * r[k] + w * r[min(k + 1, r.size - 1)])
