"""Is a recording rhythmic, and how: its stride period with a confidence, and whether the body
stays in place (a treadmill, a swing) or travels (overground), found from the positions alone.

The period is :func:`~activebonds.data.period.recording_period`'s (the autocorrelation of the
markers' coordinates, or their heights along ``up`` when it is known, each detrended); its
confidence the autocorrelation's height at that lag (:func:`~activebonds.data.period.
peak_height`: 1 where one stride repeats the last exactly). A recording is rhythmic where that
confidence reaches :data:`MIN_CONFIDENCE` and the frames hold :data:`MIN_STRIDES` strides.
Nothing here reads a marker's name, the rate or the frame count but as numbers of the data.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ....data.period import detrended, peak_height, recording_period
from ....nanstats import nanmean

MIN_CONFIDENCE = 0.5  # the autocorrelation at the period, at least
MIN_STRIDES = 3.0  # strides in the frames, at least (a period judged on fewer is a guess)
# the body travels where its centre's straight-line drift over the frames exceeds this share of
# its size (the RMS distance of the markers from their centre)
TRAVEL_SHARE = 0.5


class Cadence:
    """What a stride period of ``period`` frames means at ``rate`` Hz over ``frames`` frames
    (a dataclass with those fields)."""

    period: float
    rate: float
    frames: int

    @property
    def frequency(self) -> float:
        """Strides per second (Hz)."""
        return self.rate / self.period

    @property
    def strides(self) -> float:
        return self.frames / self.period


@dataclass(frozen=True)
class Rhythm(Cadence):
    """A recording's stride: ``period`` frames at ``rate`` Hz, ``confidence`` the
    autocorrelation at that lag, the frames it was found on, and the body's mean velocity
    (m/s per axis: zero where it stays in place)."""

    period: float
    confidence: float
    rate: float
    frames: int
    velocity: tuple[float, ...]

    @property
    def rhythmic(self) -> bool:
        """Whether a gait model is worth proposing: a confident period, enough strides."""
        return self.confidence >= MIN_CONFIDENCE and self.strides >= MIN_STRIDES

    @property
    def travels(self) -> bool:
        return bool(np.any(np.asarray(self.velocity) != 0.0))

    def line(self) -> str:
        """The rhythm in words, for the run's output."""
        where = (
            f"the body travels at {np.linalg.norm(self.velocity):.3g} m/s"
            if self.travels
            else "the body stays in place"
        )
        verdict = "rhythmic" if self.rhythmic else "not rhythmic enough for a gait model"
        return (
            f"stride period {self.period:.4g} frames ({self.frequency:.4g} Hz, "
            f"{self.strides:.3g} strides), confidence {self.confidence:.2f} (the "
            f"autocorrelation one stride apart; {MIN_CONFIDENCE:g} and {MIN_STRIDES:g} strides "
            f"needed): {verdict}; {where}"
        )


def find_rhythm(
    positions: np.ndarray,
    rate: float,
    mask: np.ndarray | None = None,
    up: Sequence[float] | None = None,
) -> Rhythm | None:
    """The rhythm of ``positions`` [F, P, D] recorded at ``rate`` Hz (``mask`` [F, P]: the
    recorded samples; ``up``: the vertical where known), or None where nothing repeats."""
    x = np.asarray(positions, np.float64)
    if mask is not None:
        x = np.where(np.asarray(mask, bool)[..., None], x, np.nan)
    period = recording_period(x, None, up)
    if not np.isfinite(period):
        return None
    confidence = peak_height(detrended(x, None, up), period)
    return Rhythm(period, confidence, float(rate), x.shape[0], body_velocity(x, rate))


def body_velocity(positions: np.ndarray, rate: float) -> tuple[float, ...]:
    """The body's mean velocity (m/s per axis) where it travels: its centre's least-squares
    straight line in time, zero where that line moves it less than :data:`TRAVEL_SHARE` of
    its size over the frames (a treadmill's sway, a swing)."""
    x = np.asarray(positions, np.float64)
    centre = nanmean(x, axis=1)  # [F, D]
    ok = np.isfinite(centre).all(axis=1)
    if ok.sum() < 3:
        return (0.0,) * x.shape[2]
    t = np.arange(x.shape[0], dtype=np.float64) / rate
    slope = np.polyfit(t[ok], centre[ok], 1)[0]  # [D] m/s
    size = float(np.sqrt(nanmean(np.sum((x - centre[:, None]) ** 2, axis=-1))))
    drift = float(np.linalg.norm(slope) * (t[ok][-1] - t[ok][0]))
    if not drift > TRAVEL_SHARE * size:
        return (0.0,) * x.shape[2]
    return tuple(float(v) for v in slope)
