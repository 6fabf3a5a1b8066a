"""A walk's stride period, found from fewer strides than the gait family's rhythm needs
(:mod:`~activebonds.identify.discover.gait.rhythm` asks for three; a gait lab's walkway holds
one or two).

The body's shape is the markers' positions about their centre in each frame (the travel
removed). A stride later the shape comes back: the period is the lag ``T`` minimising the
mean squared change of the shape over ``T`` frames, ``mismatch(T) = mean |y(t + T) -
y(t)|^2 / (2 var y)`` (0 where a stride repeats the last exactly, about 1 for no relation),
searched between :data:`SHORTEST` seconds and the frames over :data:`MIN_STRIDES` strides,
refined to a fraction of a frame by a parabola through the minimum and its neighbours. A
half stride does not repeat the shape (left and right feet swap), so the stride, not the step,
is found. The period is trusted where the mismatch is at most :data:`MAX_MISMATCH`. Nothing
here reads a marker's name, the rate or the frame count but as numbers of the data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ....nanstats import nanmean
from ..gait.rhythm import Cadence

SHORTEST = 0.4  # s: no stride of a legged body is shorter (a running human's is ~0.7 s)
MIN_STRIDES = 1.25  # strides the frames must hold: the lag compares this share of them at least
MAX_MISMATCH = 0.25  # the mismatch at the period, at most (1: no repetition)
MIN_OVERLAP = 8  # frames compared at a lag, at least


@dataclass(frozen=True)
class Stride(Cadence):
    """A stride of ``period`` frames at ``rate`` Hz; ``mismatch`` the shape's change over
    one period (0: exact repetition), ``frames`` the frames it was found on."""

    period: float
    mismatch: float
    rate: float
    frames: int

    @property
    def trusted(self) -> bool:
        return self.mismatch <= MAX_MISMATCH and self.strides >= MIN_STRIDES

    def line(self) -> str:
        return (
            f"stride {self.period:.4g} frames ({self.frequency:.4g} Hz, {self.strides:.3g} "
            f"strides), the shape's mismatch a stride apart {self.mismatch:.3f} (at most "
            f"{MAX_MISMATCH:g} trusted)"
        )


def shape(positions: np.ndarray) -> np.ndarray:
    """The markers about their centre in each frame [F, P, D] (NaN where missing)."""
    x = np.asarray(positions, np.float64)
    return x - nanmean(x, axis=1, keepdims=True)


def mismatch(y: np.ndarray, lag: int) -> float:
    """The mean squared change of shape ``y`` [F, P, D] over ``lag`` frames over twice its
    variance (NaN samples left out)."""
    var = float(nanmean(np.sum((y - nanmean(y, axis=0)) ** 2, axis=-1)))
    if not var > 0:
        return np.inf
    d = np.sum((y[lag:] - y[:-lag]) ** 2, axis=-1)
    return float(nanmean(d)) / (2.0 * var) if np.isfinite(d).any() else np.inf


def find_stride(positions: np.ndarray, rate: float) -> Stride | None:
    """The stride of ``positions`` [F, P, D] (NaN where missing) recorded at ``rate`` Hz, or
    None where the frames are too few to compare a stride with the next or the mismatch has
    no minimum inside the lags searched."""
    y = shape(positions)
    f = y.shape[0]
    lo = max(2, int(np.floor(SHORTEST * rate)))
    hi = min(int(np.floor(f / MIN_STRIDES)), f - MIN_OVERLAP)
    if hi < lo + 2:
        return None
    lags = np.arange(lo, hi + 1)
    m = np.array([mismatch(y, int(k)) for k in lags])
    if not np.isfinite(m).any():
        return None
    i = int(np.nanargmin(np.where(np.isfinite(m), m, np.nan)))
    if i == 0 or i == len(lags) - 1:  # at the search's edge: no minimum inside it
        return None
    a, b, c = m[i - 1], m[i], m[i + 1]
    curve = a - 2.0 * b + c
    shift = 0.5 * (a - c) / curve if curve > 0 else 0.0
    shift = float(np.clip(shift, -0.5, 0.5))
    low = float(b - 0.25 * (a - c) * shift)
    return Stride(float(lags[i]) + shift, max(low, 0.0), float(rate), f)
