"""The PCA fill as a prior of the model's fill (``fill --prior pca``): its targets, the standard
deviations measured on artificial gaps, inflated by the errors' autocorrelation, and the
weight of a prior sample against a recorded one."""

from __future__ import annotations

import numpy as np

from .uncertainty import noise_estimate

SHAPE = True  # a second prior on the missing marker's steps from frame to frame


def pca_prior(positions: np.ndarray, mask: np.ndarray, gaps):
    """The PCA fill as a prior on the gaps' samples: (targets [F, M, D], the standard
    deviation per coordinate [F, M] that a sample of it is given, that of its motion from
    frame t to t + 1 within the gap [F, M] (at t); NaN off the gaps).

    The targets are Gløersen & Federolf's reconstruction (:func:`.data.fill.fill_pca`). The
    deviation comes from the PCA fill's own errors, cross-validated: the same fill of up to
    ``TRIALS`` artificial gaps of the gap's length and marker placed in complete stretches of
    the record (those frames are then not complete, so never among its training frames;
    :func:`.data.fill.self_test_errors`). Their RMS per coordinate ``sigma`` (floored at the
    markers' noise) is inflated by ``sqrt(tau)``, ``tau`` the errors' integrated
    autocorrelation along the gap (:func:`error_correlation`): the PCA fill's error is an
    offset that drifts slowly, so ``L`` samples of it know about as much as ``L / tau``
    independent ones, and fitted as independent observations they would pull the trajectory
    as if they knew ``tau`` times more. The PCA fill's motion inside the gap (its step from
    one frame to the next) is often better than where it puts the marker (its error is
    mostly an offset): its steps' errors, measured the same way, give the deviation of a
    second prior, on the missing marker's steps. NaN for a gap with no room for a test."""
    from ...data.fill import fill_pca, self_test_errors

    targets = fill_pca(positions, mask, gaps)
    sigma = np.full(mask.shape, np.nan)
    shape = np.full(mask.shape, np.nan)
    noise = noise_estimate(positions, mask)
    floor = noise if np.isfinite(noise) else 0.0
    tested: dict[tuple[int, int], tuple[float, float]] = {}
    for g in gaps:
        key = (g.column, g.length)
        if key not in tested:
            e = self_test_errors(fill_pca, positions, mask, g.column, g.length, others=True)
            if not len(e):
                tested[key] = (float("nan"), float("nan"))
            else:
                rms = max(float(np.sqrt(np.mean(e**2))), floor)
                level = rms * float(np.sqrt(error_correlation(e)))
                steps = np.diff(e, axis=1)  # the errors of its frame-to-frame motion
                if steps.shape[1] and SHAPE:
                    step_rms = max(float(np.sqrt(np.mean(steps**2))), floor * np.sqrt(2.0))
                    step = step_rms * float(np.sqrt(error_correlation(steps)))
                else:
                    step = float("nan")
                tested[key] = (level, step)
        sigma[g.start : g.stop, g.column] = tested[key][0]
        shape[g.start : g.stop - 1, g.column] = tested[key][1]
    return targets, sigma, shape


def error_correlation(errors: np.ndarray) -> float:
    """How many samples of a gap's errors count as one: ``tau = 1 + 2 sum_lag (1 - lag / L)
    rho_lag`` over lags 1 to ``L`` - 1 while ``rho`` stays positive, ``rho_lag`` the errors'
    autocorrelation (about zero, not their mean: an offset is the correlated part), pooled
    over ``errors`` [trials, L, D]; between 1 and ``L`` (a constant offset)."""
    n = errors.shape[1]
    v = float(np.mean(errors**2))
    if not v > 0.0:
        return 1.0
    tau = 1.0
    for lag in range(1, n):
        rho = float(np.mean(errors[:, lag:] * errors[:, :-lag])) / v
        if not rho > 0.0:
            break
        tau += 2.0 * (1.0 - lag / n) * rho
    return float(np.clip(tau, 1.0, n))


def prior_weight(level: float, sigma: np.ndarray) -> np.ndarray:
    """The weight of a prior sample of standard deviation ``sigma`` (m per coordinate) against
    a position error of weight 1 that stands for ``level`` m (the fit's scaled residual SD):
    ``level / sigma``, so that the prior adds its information ``1 / sigma^2`` to the model's
    (inverse-variance fusion); at most 1 (never more than a recorded sample), 0 where
    ``sigma`` is NaN."""
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(np.isfinite(sigma) & (sigma > 0), level / sigma, 0.0)
    return np.clip(w, 0.0, 1.0)
