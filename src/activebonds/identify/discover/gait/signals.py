"""The signals an entrained drive may read (a marker's coordinate along an axis, or the
distance between two markers), how periodic each is at the stride, and the pair that reads the
gait's phase evenly (DESIGN.md §2, "Entrained drive").

A signal's periodicity is the share of its variance (mean removed) in the stride's fundamental:
the least squares of a cosine and a sine at the stride frequency, ``s ~ A cos(2 pi f t -
theta)``. The drive reads the most periodic one; its partner, read against ``sin psi``, is the
most periodic of those whose fundamental lies a quarter stride from it (90 +-
:data:`QUARTER_TOLERANCE` degrees). Their gains come from a coupling strength ``kappa``
(the lock range as a share of the drive's rate, ``sigma A / 2 / (2 pi f)``), the partner's
balanced (``sigma_b A_b = sigma A sin(theta_b - theta)``: the pull along the stride even).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ....axes import AXES
from ....nanstats import nanmean

QUARTER_TOLERANCE = np.radians(30.0)


@dataclass(frozen=True)
class Signal:
    """One signal: ``particles`` (one index and an ``axis``: a coordinate; two: a distance),
    its mean over the frames it was surveyed on (the coupling's offset), its fundamental's
    amplitude (m) and phase theta (rad), and ``share``: its variance's share in the
    fundamental."""

    particles: tuple[int, ...]
    axis: int | None
    offset: float
    amplitude: float
    phase: float
    share: float

    def values(self, positions: np.ndarray) -> np.ndarray:
        """The signal along positions [F, P, D], before its offset."""
        x = np.asarray(positions, np.float64)
        if len(self.particles) == 1:
            return x[:, self.particles[0], self.axis]
        a, b = self.particles
        return np.linalg.norm(x[:, b] - x[:, a], axis=-1)

    def table(self, names, gain: float) -> dict:
        """The model file's keys of this signal read at ``gain``."""
        if len(self.particles) == 1:
            keys = {"signal": "height", "particle": names[self.particles[0]]}
            keys["axis"] = AXES[self.axis]
        else:
            keys = {"signal": "length", "particles": [names[i] for i in self.particles]}
        return keys | {"gain": float(gain), "offset": self.offset}

    def text(self, names) -> str:
        if len(self.particles) == 1:
            return f"{names[self.particles[0]]}'s {AXES[self.axis]}"
        a, b = (names[i] for i in self.particles)
        return f"the distance {a}-{b}"


def fundamental(s: np.ndarray, frequency: float, rate: float) -> tuple[float, float, float]:
    """(share, amplitude, theta) of a signal's fundamental at ``frequency`` Hz (NaN samples
    left out): ``s - mean ~ A cos(2 pi f t - theta)``, t from the first frame."""
    s = np.asarray(s, np.float64)
    t = np.arange(s.size) / rate
    ok = np.isfinite(s)
    if ok.sum() < 4:
        return 0.0, 0.0, 0.0
    y = s[ok] - s[ok].mean()
    w = 2.0 * np.pi * frequency * t[ok]
    basis = np.stack([np.cos(w), np.sin(w)], axis=1)
    c, *_ = np.linalg.lstsq(basis, y, rcond=None)
    total = float(np.sum(y * y))
    share = float(np.sum((basis @ c) ** 2) / total) if total > 0 else 0.0
    return share, float(np.hypot(*c)), float(np.arctan2(c[1], c[0]))


def survey(
    positions: np.ndarray, frequency: float, rate: float, axes: tuple[int, ...]
) -> list[Signal]:
    """Every signal of ``positions`` [F, P, D]: each marker's coordinate along each of
    ``axes`` and each pair's distance, most periodic first."""
    x = np.asarray(positions, np.float64)
    p = x.shape[1]
    found = [((i,), a) for i in range(p) for a in axes]
    found += [((i, j), None) for i in range(p) for j in range(i + 1, p)]
    out = []
    for particles, axis in found:
        probe = Signal(particles, axis, 0.0, 0.0, 0.0, 0.0)
        s = probe.values(x)
        if not np.isfinite(s).any():
            continue
        share, amplitude, theta = fundamental(s, frequency, rate)
        if amplitude > 0:
            out.append(Signal(particles, axis, float(nanmean(s)), amplitude, theta, share))
    return sorted(out, key=lambda s: -s.share)


def partner(signals: list[Signal], first: Signal) -> Signal | None:
    """The most periodic signal of ``signals`` (most periodic first) a quarter stride from
    ``first`` (90 +- :data:`QUARTER_TOLERANCE` degrees apart), not reading the same
    particles; None where there is none."""
    for s in signals:
        if s.particles == first.particles:
            continue
        apart = abs((s.phase - first.phase + np.pi) % (2 * np.pi) - np.pi)
        if abs(apart - np.pi / 2) <= QUARTER_TOLERANCE:
            return s
    return None


def gain_for(signal: Signal, kappa: float, frequency: float) -> float:
    """The gain sigma (rad/s per m) giving ``signal`` the coupling strength ``kappa``:
    sigma A / 2 / (2 pi f) = kappa."""
    return float(kappa * 2.0 * (2.0 * np.pi * frequency) / signal.amplitude)


def balanced_gain(first: Signal, gain: float, second: Signal) -> float:
    """The partner's gain pairing it with ``first`` read at ``gain``: sigma_b = sigma A
    sin(theta_b - theta) / A_b (negative where the partner leads)."""
    return float(gain * first.amplitude * np.sin(second.phase - first.phase) / second.amplitude)
