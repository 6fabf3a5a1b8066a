"""K frames ahead: the model's free run from every recorded state, beside zero force's.

From each start frame ``s`` whose frames ``s - 1`` and ``s`` are complete, the model runs K
frames on its own (the start velocity from those two frames, as the fit cost's, so K = 1 is
the one-step prediction) and its position at ``s + K`` is compared with the recording; the
zero-force (constant-velocity) predictor gives ``x_s + K (x_s - x_{s-1})``. The RMS over every
(start, marker) term whose target is recorded, overall and per marker, is a
:class:`~activebonds.identify.judge.verdict.Comparison`; a non-finite prediction of a recorded
target makes its marker's RMS, and the overall one, +inf.

The model's time starts at the window's first frame (``offset``: frames from the model's time
origin to the window, as :func:`~activebonds.identify.judge.metrics.free_run_metrics`); an entrained
drive's phase at each start is tracked along the window
(:func:`~activebonds.identify.judge.predictions.tracked_phases`).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ...data import Trajectory
from ...model import Model
from ...runtime import float64
from .predictions import StaticTopology, float64_params, solved, tracked_phases
from .verdict import Comparison

DEFAULT_AHEAD = 10  # frames ahead in fit's summary and evaluate's default


@partial(jax.jit, static_argnames=("topo", "n_steps", "substeps", "method", "newton"))
def _runs(
    params,
    x_prev,
    x0,
    t0,
    dt,
    topo: StaticTopology,
    n_steps,
    substeps,
    method,
    psis=None,
    newton: bool = False,
):
    """(start velocities, the runs' last positions): ``psis``, an entrained drive's phases at
    the frames of ``x_prev`` and ``x0``; ``newton``, the start velocities by Newton's method
    (:func:`.predictions.solved`)."""
    from ...physics.integrate import rollout_states, start_velocity

    def one(a, b, t, *psi):
        p_prev, p0 = psi if psi else (None, None)
        v = start_velocity(
            params, topo.topo, a, b, dt, substeps, method, t=t, psi=p_prev, newton=newton
        )
        xs = rollout_states(params, topo.topo, b, v, dt, n_steps, substeps, method, t, p0)[0]
        return v, xs[-1]

    return jax.vmap(one)(x_prev, x0, t0, *(psis or ()))


def _starts(rec: np.ndarray, k: int) -> np.ndarray:
    """Start frames s with frames s - 1 and s complete and a frame s + k in the window."""
    complete = np.isfinite(rec).all(axis=(1, 2))
    s = np.arange(1, rec.shape[0] - k)
    return s[complete[s] & complete[s - 1]] if s.size else s


@float64
def model_ahead(
    model: Model,
    positions: np.ndarray,
    dt: float,
    k: int,
    substeps: int = 1,
    method: str = "euler",
    offset: int = 0,
) -> np.ndarray:
    """The model's prediction of each frame ``s + k`` from the recorded state at ``s``,
    aligned with the recording [F, P, D]: NaN where there is no start (and +inf where the
    run went non-finite)."""
    rec = np.asarray(positions, np.float64)
    out = np.full_like(rec, np.nan)
    starts = _starts(rec, k)
    if starts.size == 0:
        return out
    psi = tracked_phases(model, rec, dt, substeps, offset)  # an entrained drive's, else None
    psis = None if psi is None else (jnp.asarray(psi[starts - 1]), jnp.asarray(psi[starts]))
    pred = solved(
        _runs,
        float64_params(model),
        jnp.asarray(rec[starts - 1]),
        jnp.asarray(rec[starts]),
        jnp.asarray((starts + int(offset)) * float(dt)),
        float(dt),
        topo=StaticTopology(model.topology),
        n_steps=int(k),
        substeps=int(substeps),
        method=method,
        psis=psis,
    )[1]
    pred = np.array(pred, np.float64)
    pred[~np.isfinite(pred)] = np.inf  # a failed prediction: an infinite error, not a gap
    out[starts + k] = pred
    return out


def zero_force_ahead(positions: np.ndarray, k: int) -> np.ndarray:
    """The constant-velocity prediction of each frame ``s + k`` from frames ``s - 1``, ``s``
    [F, P, D] (NaN where there is no start)."""
    rec = np.asarray(positions, np.float64)
    out = np.full_like(rec, np.nan)
    starts = _starts(rec, k)
    out[starts + k] = rec[starts] + k * (rec[starts] - rec[starts - 1])
    return out


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


def compare(
    model: Model,
    trajectory: Trajectory,
    k: int = 1,
    *,
    substeps: int = 1,
    method: str = "euler",
    offset: int = 0,
) -> Comparison:
    """The model and zero force ``k`` frames ahead on ``trajectory`` (markers in the model's
    particle order)."""
    rec = np.asarray(trajectory.positions, np.float64)
    k = int(k)
    mine = model_ahead(model, rec, trajectory.dt, k, substeps, method, offset)
    zero = zero_force_ahead(rec, k)
    m, m_per, terms = _rms(mine, rec)
    z, z_per, _ = _rms(zero, rec)
    return Comparison(
        horizon=k,
        model_mm=m,
        zero_force_mm=z,
        markers=tuple(trajectory.markers),
        model_per_marker=tuple(float(x) for x in m_per),
        zero_force_per_marker=tuple(float(x) for x in z_per),
        terms=terms,
    )


def comparisons(
    model: Model,
    trajectory: Trajectory,
    horizon: int = DEFAULT_AHEAD,
    *,
    substeps: int = 1,
    method: str = "euler",
    offset: int = 0,
) -> list[Comparison]:
    """One step and ``horizon`` frames ahead (only one step when ``horizon`` is 1, or when
    the window is too short for ``horizon``: it is clipped to the frames there are)."""
    n = trajectory.n_frames
    ks = [1]
    h = min(int(horizon), max(n - 2, 1))
    if h > 1:
        ks.append(h)
    return [
        compare(model, trajectory, k, substeps=substeps, method=method, offset=offset) for k in ks
    ]
