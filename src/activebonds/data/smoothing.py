"""Savitzky-Golay smoothing of recorded positions, gap by gap (never across a gap).

Marker noise enters the one-step cost through its inputs: the restart positions and, above
all, the backward-difference velocities (noise sigma becomes sqrt(2) sigma / dt of velocity
noise). A least-squares fit with noisy inputs is biased (errors in variables): dampings come
out far too large. Smoothing the inputs with a local polynomial (Savitzky & Golay 1964; SciPy's
``savgol_filter``) removes most of that noise while keeping motion up to the polynomial's
order exact. Each marker is smoothed separately over each run of consecutive recorded frames;
a run shorter than the window is left as recorded, and a gap stays a gap.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

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
