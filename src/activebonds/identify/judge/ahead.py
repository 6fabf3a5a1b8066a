"""K frames ahead: the model's free run from every recorded state, beside zero force's.

From each start frame ``s``, for each marker whose particles that can move it within K frames
(itself, its bonded neighbours within K hops, K times the substeps) are recorded at frames
``s - 1`` and ``s`` (the fit's rule: :mod:`~activebonds.identify.costs.windows`; the missing
others filled, and never read by a counted term), the model runs K frames on its own (the start velocity from those two frames, as the fit cost's, so K = 1 is
the one-step prediction) and its position at ``s + K`` is compared with the recording; the
zero-force (constant-velocity) predictor gives ``x_s + K (x_s - x_{s-1})`` on the same terms.
The RMS over every (start, marker) term whose target is recorded, overall and per marker, is a
:class:`~activebonds.identify.judge.verdict.Comparison`; a non-finite prediction of a recorded
target makes its marker's RMS, and the overall one, +inf.

The model's time starts at the window's first frame (``offset``: frames from the model's time
origin to the window, as :func:`~activebonds.identify.judge.metrics.free_run_metrics`); an entrained
drive's phase at each start is tracked along the window. The predictions are
:mod:`~activebonds.identify.judge.predictions`' (:func:`~.predictions.model_ahead`,
:func:`~.predictions.zero_force_ahead`); this module scores them.
"""

from __future__ import annotations

import numpy as np

from ...data import Trajectory
from ...model import Model
from .predictions import ahead_terms, model_ahead, zero_force_ahead
from .verdict import Comparison

DEFAULT_AHEAD = 10  # frames ahead in fit's summary and evaluate's default


def _rms(pred: np.ndarray, rec: np.ndarray) -> tuple[float, np.ndarray, int]:
    """(overall RMS mm, per-marker RMS mm [P], terms) over the terms with a prediction and a
    recorded target; an infinite prediction there gives +inf."""
    has = ~np.isnan(pred).any(axis=-1) & np.isfinite(rec).all(axis=-1)  # [F, P]
    with np.errstate(over="ignore", invalid="ignore"):
        err2 = np.where(has, np.sum((pred - rec) ** 2, axis=-1), 0.0)
    err2 = np.where(has & ~np.isfinite(err2), np.inf, err2)
    n = has.sum(axis=0)
    total = err2.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        per = np.where(n > 0, np.sqrt(total / np.maximum(n, 1)) * 1000.0, np.nan)
    terms = int(n.sum())
    overall = float(np.sqrt(total.sum() / terms) * 1000.0) if terms else float("nan")
    return overall, per, terms


def compare(model: Model, trajectory: Trajectory, k: int = 1, **run) -> Comparison:
    """The model and zero force ``k`` frames ahead on ``trajectory`` (markers in the model's
    particle order; ``run``: ``substeps``, ``method`` and ``offset``, as
    :func:`~activebonds.identify.judge.predictions.model_ahead`'s)."""
    from ..costs.windows import fill_missing, neighbours_of, reach_of

    rec = np.asarray(trajectory.positions, np.float64)
    k = int(k)
    reach = reach_of(neighbours_of(model), k * int(run.get("substeps", 1)))
    starts, counts = ahead_terms(rec, k, reach)
    terms = (starts, counts, fill_missing(rec, np.isfinite(rec).all(axis=-1)))
    m, m_per, n = _rms(model_ahead(model, rec, trajectory.dt, k, terms=terms, **run), rec)
    z, z_per, _ = _rms(zero_force_ahead(rec, k, terms), rec)
    return Comparison(
        horizon=k,
        model_mm=m,
        zero_force_mm=z,
        markers=tuple(trajectory.markers),
        model_per_marker=tuple(float(x) for x in m_per),
        zero_force_per_marker=tuple(float(x) for x in z_per),
        terms=n,
    )


def comparisons(
    model: Model, trajectory: Trajectory, horizon: int = DEFAULT_AHEAD, **run
) -> list[Comparison]:
    """One step and ``horizon`` frames ahead (only one step when ``horizon`` is 1, or when
    the window is too short for ``horizon``: it is clipped to the frames there are;
    ``run``: as :func:`compare`'s)."""
    n = trajectory.n_frames
    ks = [1]
    h = min(int(horizon), max(n - 2, 1))
    if h > 1:
        ks.append(h)
    return [compare(model, trajectory, k, **run) for k in ks]
