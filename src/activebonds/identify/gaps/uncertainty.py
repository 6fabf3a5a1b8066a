"""How sure the model's fill is: the markers' noise from the record alone, the integrated
autocorrelation of the fit's continuity defects, and the factor they put on the Gauss-Newton
standard error of a filled sample (the scaling described in :mod:`.fill`)."""

from __future__ import annotations

import numpy as np


def noise_estimate(positions: np.ndarray, mask: np.ndarray) -> float:
    """The markers' noise (m, per coordinate) from the record alone: the fourth difference of
    every marker's present samples (five consecutive frames), whose standard deviation is
    ``sqrt(70)`` times the noise's for white noise on a motion smooth at the frame rate; its
    median absolute value (over 0.6745, robust to impacts) over ``sqrt(70)``. NaN with fewer
    than 10 such differences."""
    x, m = positions, mask
    ok = m[:-4] & m[1:-3] & m[2:-2] & m[3:-1] & m[4:]
    d4 = x[4:] - 4 * x[3:-1] + 6 * x[2:-2] - 4 * x[1:-3] + x[:-4]
    values = np.abs(d4[ok]).ravel()
    if values.size < 10:
        return float("nan")
    return float(np.median(values) / 0.6745 / np.sqrt(70.0))


def defect_correlation(defects: np.ndarray, longest: int) -> float:
    """The integrated autocorrelation ``tau = 1 + 2 sum rho_lag`` of the continuity defects
    ``defects`` [K, n] (one series per coordinate, each less its mean), over lags 1 to
    ``longest`` - 1 while ``rho`` stays positive; at least 1."""
    e = defects - defects.mean(axis=0)
    v = float(np.mean(e**2))
    if not v > 0.0:
        return 1.0
    tau = 1.0
    for lag in range(1, min(int(longest), len(e))):
        rho = float(np.mean(e[lag:] * e[:-lag])) / v
        if not rho > 0.0:
            break
        tau += 2.0 * rho
    return tau


def error_scale(sigma_fit: float, sigma_noise: float, tau: float) -> float:
    """The factor on the posterior SD at ``sigma_fit`` (see the module's docstring):
    ``max(sigma_noise, sigma_fit) / sigma_fit * sqrt(tau)``; with ``sigma_fit`` 0 (an exact
    fit), 1 (the SD is 0 and the noise floor is applied by the caller)."""
    floor = sigma_noise if np.isfinite(sigma_noise) else 0.0
    level = max(floor, sigma_fit) / sigma_fit if sigma_fit > 0.0 else 1.0
    return float(level * np.sqrt(max(tau, 1.0)))
