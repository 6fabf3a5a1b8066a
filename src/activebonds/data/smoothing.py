"""Savitzky-Golay smoothing of recorded positions, gap by gap (never across a gap).

Marker noise enters the one-step cost through its inputs: the restart positions and, above
all, the backward-difference velocities (noise sigma becomes sqrt(2) sigma / dt of velocity
noise). A least-squares fit with noisy inputs is biased (errors in variables): dampings come
out far too large. Smoothing the inputs with a local polynomial (Savitzky & Golay 1964; SciPy's
``savgol_filter``) removes most of that noise while keeping motion up to the polynomial's
order exact. Each marker is smoothed separately over each run of consecutive recorded frames;
a run shorter than the window is left as recorded, and a gap stays a gap.

How noisy a recording is, and which window makes its one-step scores judge the motion rather
than the noise: :func:`noise_of`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ORDER = 3  # polynomial order: a cubic motion passes unchanged


def check_window(window: int) -> int:
    """``window`` (frames) if usable: 0 (no smoothing) or odd and above the order + 1."""
    window = int(window)
    if window != 0 and (window % 2 == 0 or window <= ORDER + 1):
        raise ValueError(
            f"a smoothing window is 0 (off) or an odd number of frames >= 5, got {window}"
        )
    return window


def smooth_positions(positions: np.ndarray, mask: np.ndarray, window: int) -> np.ndarray:
    """Positions [F, P, D] smoothed over ``window`` frames per marker and run of recorded
    frames (``mask`` [F, P]); NaN where missing, as given."""
    from scipy.signal import savgol_filter  # here: scipy.signal takes half a second

    window = check_window(window)
    out = np.array(positions, dtype=np.float64, copy=True)
    if window == 0:
        return out
    for p in range(out.shape[1]):
        seen = np.asarray(mask[:, p], bool)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], seen.astype(np.int8), [0]])))
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            if stop - start >= window:
                out[start:stop, p] = savgol_filter(out[start:stop, p], window, ORDER, axis=0)
    return out


WINDOWS = (5, 7, 9, 11, 15, 21, 31, 41)  # the windows noise_window chooses from
NOISE_SHARE = 0.25  # the smoothed noise's one-step floor at most this share of the motion's


@dataclass(frozen=True)
class Noise:
    """What a recording's marker noise does to one-step scores (every figure in mm).

    ``sigma``: the noise per coordinate, from the fourth differences (white noise of
    variance s^2 gives them 70 s^2; a motion sampled finely enough adds almost nothing), by
    the median so that a few sharp events do not count: ``median |d4| / (0.6745 sqrt(70))``.
    ``floor``: the zero-force predictor's one-step RMS that noise alone gives (its second
    difference: ``sqrt(6 D) sigma``). ``zero_force``: that predictor's one-step RMS over the
    recording; ``motion``: its part the noise does not explain, ``sqrt(zero_force^2 -
    floor^2)``. ``window``: the smallest Savitzky-Golay window (:data:`WINDOWS`, 0: none)
    after which the noise's floor is at most :data:`NOISE_SHARE` of ``motion``, or the
    largest where none is."""

    sigma: float
    floor: float
    zero_force: float
    motion: float
    window: int

    @property
    def dominated(self) -> bool:
        return self.window != 0

    def line(self) -> str:
        """The noise in words: its size, its one-step floor beside zero force's error."""
        return (
            f"marker noise about {self.sigma:.3g} mm (fourth differences): its one-step floor "
            f"{self.floor:.3g} mm of zero force's {self.zero_force:.3g} mm"
        )


def noise_of(positions: np.ndarray) -> Noise:
    """:class:`Noise` of positions [F, P, D] (metres; NaN where missing)."""
    x = np.asarray(positions, np.float64)
    d4 = np.diff(x, 4, axis=0)
    d4 = np.abs(d4[np.isfinite(d4)])
    sigma = float(np.median(d4) / (0.6745 * np.sqrt(70.0))) if d4.size else 0.0
    acc = x[2:] - 2 * x[1:-1] + x[:-2]
    err2 = np.sum(acc**2, axis=-1)
    err2 = err2[np.isfinite(err2)]
    zero = float(np.sqrt(err2.mean())) if err2.size else 0.0
    floor = float(np.sqrt(6.0 * x.shape[-1]) * sigma)
    motion = float(np.sqrt(max(zero**2 - floor**2, 0.0)))
    window = 0
    if floor > NOISE_SHARE * motion:
        gains = {w: _second_difference_gain(w) for w in WINDOWS}
        fits = [w for w in WINDOWS if floor * gains[w] <= NOISE_SHARE * motion]
        window = fits[0] if fits else WINDOWS[-1]
    mm = 1000.0
    return Noise(sigma * mm, floor * mm, zero * mm, motion * mm, window)


def _second_difference_gain(window: int) -> float:
    """How much a cubic Savitzky-Golay window scales white noise's second difference."""
    from scipy.signal import savgol_coeffs  # here: scipy.signal takes half a second

    h = np.convolve(savgol_coeffs(window, ORDER), [1.0, -2.0, 1.0])
    return float(np.sqrt(np.sum(h**2) / 6.0))
