"""What an identified model predicts: one-step predictions, a free run, errors, neurons.

One-step predictions are made as the cost makes them (DESIGN.md §3): frame t is predicted
from the *recorded* state at t - 1, with the velocity the integrator carries there given
``x[t-2]`` and ``x[t-1]`` (:func:`~activebonds.physics.integrate.start_velocity`; the
backward difference for one-substep Euler). The free run starts from the first two recorded frames and never
looks at the data again. Everything is float64 NumPy; NaN marks what cannot be predicted
(missing inputs, before the start, or after a free run went non-finite).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .. import bonds
from ..data import Trajectory
from ..model import Model, Params, Topology
from ..physics import advance, neuron_activity, rollout_states, start_velocity
from ..runtime import float64
from .runs import RunRecord, load_run, original_window

SATURATION = 0.95  # |a| above this: a saturated neuron
NEAR_ZERO = 0.01  # |w| below this fraction of the weight range: a near-zero weight


class _Topo:
    """A topology as a static jit argument, equal by content: compiled predictions are reused
    across models of the same shape (e.g. the runs of a series)."""

    def __init__(self, topo: Topology):
        self.topo = topo
        self.key = (
            topo.n_particles,
            topo.dimension,
            tuple(sorted(topo.disabled)),
            *(
                (kind, name, a.shape, a.tobytes())
                for kind, arrays in topo.bonds.items()
                for name, a in arrays.items()
            ),
        )

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other) -> bool:
        return isinstance(other, _Topo) and other.key == self.key


def _params(model: Model) -> Params:
    return jax.tree_util.tree_map(lambda a: jnp.asarray(np.asarray(a, np.float64)), model.params)


def neural_kinds(topo: Topology) -> tuple[str, ...]:
    """The kinds whose bonds may carry a neuron (binary bonds), in registry order: the
    report's per-bond rows (labels, activations, weights) are their bonds, in this order."""
    return tuple(k for k in topo.bonds if bonds.get(k).activity is not None)


def neural_bonds(topo: Topology) -> tuple[np.ndarray, np.ndarray]:
    """Particle indices [B, arity] of the bonds of :func:`neural_kinds` and which carry a
    neuron [B] (a kind's ``neural`` flag)."""
    rows, flags = [], []
    for k in neural_kinds(topo):
        arrays = topo.bonds[k]
        rows.append(np.asarray(arrays["particles"], np.int64))
        flags.append(np.asarray(arrays.get("neural", np.ones(len(rows[-1]), bool)), bool))
    if not rows:
        return np.zeros((0, 2), np.int64), np.zeros(0, bool)
    return np.concatenate(rows), np.concatenate(flags)


@partial(jax.jit, static_argnames=("topo", "substeps", "method"))
def _one_step(params, x_prev, x0, times, dt, topo: _Topo, substeps: int, method: str):
    def step(a, b, t):
        v = start_velocity(params, topo.topo, a, b, dt, substeps, method, t=t)
        return advance(params, topo.topo, b, v, dt, substeps, method, t)[0]

    return jax.vmap(step)(x_prev, x0, times)


@partial(jax.jit, static_argnames=("topo", "n_steps", "substeps", "method"))
def _free_run(params, x_prev, x0, t0, dt, topo: _Topo, n_steps: int, substeps: int, method: str):
    v0 = start_velocity(params, topo.topo, x_prev, x0, dt, substeps, method, t=t0)
    xs, vs = rollout_states(params, topo.topo, x0, v0, dt, n_steps, substeps, method, t0)
    return v0, xs, vs


@partial(jax.jit, static_argnames=("topo",))
def _activations(params, xs, vs, ts, topo: _Topo):
    return jax.vmap(lambda x, v, t: neuron_activity(params, topo.topo, x, v, t))(xs, vs, ts)


@float64
def one_step(
    model: Model, positions: np.ndarray, dt: float, substeps: int = 1, method: str = "euler"
) -> np.ndarray:
    """Prediction of every frame t >= 2 from the recorded frames t - 1 and t - 2, [F, P, D].

    NaN where an input frame misses a marker, and for frames 0 and 1. Time is 0 at frame 0
    (the fitted window's first frame)."""
    x = np.asarray(positions, dtype=np.float64)
    out = np.full_like(x, np.nan)
    if x.shape[0] < 3:
        return out
    prev, prev2 = x[1:-1], x[:-2]
    ok = np.isfinite(prev).all(axis=(1, 2)) & np.isfinite(prev2).all(axis=(1, 2))
    x0 = np.where(ok[:, None, None], prev, 0.0)
    x_prev = np.where(ok[:, None, None], prev2, 0.0)
    pred = _one_step(
        _params(model),
        jnp.asarray(x_prev),
        jnp.asarray(x0),
        jnp.arange(1, x.shape[0] - 1) * float(dt),
        float(dt),
        topo=_Topo(model.topology),
        substeps=int(substeps),
        method=method,
    )
    pred = np.array(pred, dtype=np.float64)
    pred[~ok] = np.nan
    out[2:] = pred
    return _finite_or_nan(out)


@float64
def free_run(
    model: Model,
    positions: np.ndarray,
    dt: float,
    n_frames: int | None = None,
    substeps: int = 1,
    method: str = "euler",
) -> tuple[np.ndarray, np.ndarray]:
    """Free run from the first two complete consecutive recorded frames.

    Returns positions and velocities [n_frames, P, D] (velocities are the model's own state;
    frames before the start are the recording and NaN velocities). Once a frame goes
    non-finite, it and every later frame are NaN."""
    x = np.asarray(positions, dtype=np.float64)
    n = x.shape[0] if n_frames is None else int(n_frames)
    xs = np.full((n, *x.shape[1:]), np.nan)
    vs = np.full_like(xs, np.nan)
    complete = np.isfinite(x).all(axis=(1, 2))
    starts = np.flatnonzero(complete[1:] & complete[:-1]) + 1
    if starts.size == 0 or starts[0] >= n:
        return xs, vs
    s = int(starts[0])
    xs[: s + 1] = x[: s + 1]
    run = _free_run(
        _params(model),
        jnp.asarray(x[s - 1]),
        jnp.asarray(x[s]),
        s * float(dt),
        float(dt),
        topo=_Topo(model.topology),
        n_steps=max(n - s - 1, 1),
        substeps=int(substeps),
        method=method,
    )
    vs[s] = np.asarray(run[0], dtype=np.float64)
    if n - s - 1 > 0:
        xs[s + 1 :] = np.array(run[1], dtype=np.float64)
        vs[s + 1 :] = np.asarray(run[2], dtype=np.float64)
    bad = ~(np.isfinite(xs).all(axis=(1, 2)) & np.isfinite(vs).all(axis=(1, 2)))
    bad[: s + 1] = False
    if bad.any():
        first = int(np.argmax(bad))
        xs[first:] = np.nan
        vs[first:] = np.nan
    return xs, vs


def _finite_or_nan(a: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(a), a, np.nan)


def to_mm(a: np.ndarray) -> np.ndarray:
    """Metres to millimetres; values too large to show (or non-finite) become NaN."""
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.asarray(a, np.float64) * 1000.0
    return np.where(np.abs(out) < 1e12, out, np.nan)


def rms_mm(predicted: np.ndarray, recorded: np.ndarray, frames=slice(None)) -> np.ndarray:
    """Per-particle RMS position error (mm) over ``frames`` where both are known, [P].

    A particle with nothing to compare gets NaN."""
    p = np.asarray(predicted, dtype=np.float64)[frames]
    r = np.asarray(recorded, dtype=np.float64)[frames]
    with np.errstate(over="ignore", invalid="ignore"):
        err2 = np.sum((p - r) ** 2, axis=-1)  # [F, P]
    ok = ~np.isnan(err2)  # a finite prediction too far to square still counts (as inf)
    n = ok.sum(axis=0)
    total = np.where(ok, err2, 0.0).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        return np.where(n > 0, np.sqrt(total / np.maximum(n, 1)) * 1000.0, np.nan)


def error_mm(predicted: np.ndarray, recorded: np.ndarray) -> np.ndarray:
    """Distance between prediction and recording per frame and particle (mm), [F, P]."""
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.asarray(predicted, np.float64) - np.asarray(recorded, np.float64)
        return np.sqrt(np.sum(d * d, axis=-1)) * 1000.0


@float64
def activations(model: Model, xs: np.ndarray, vs: np.ndarray, dt: float = 0.0) -> np.ndarray:
    """Neuron activations at each state (x, v) of frames 0, 1, ... (time ``frame * dt``, for
    a rhythmic drive), [F, B]; 0 for non-neural bonds, NaN where the state is unknown."""
    xs = np.asarray(xs, np.float64)
    vs = np.asarray(vs, np.float64)
    n_b = len(neural_bonds(model.topology)[1])
    out = np.full((xs.shape[0], n_b), np.nan)
    if n_b == 0:
        return out
    ok = np.isfinite(xs).all(axis=(1, 2)) & np.isfinite(vs).all(axis=(1, 2))
    if not ok.any():
        return out
    ts = jnp.asarray(np.arange(xs.shape[0])[ok] * float(dt))
    act = _activations(
        _params(model), jnp.asarray(xs[ok]), jnp.asarray(vs[ok]), ts, topo=_Topo(model.topology)
    )
    out[ok] = np.asarray(act, np.float64)
    return out


def saturation_share(act: np.ndarray, neural: np.ndarray, limit: float = SATURATION):
    """Share of (frame, neuron) samples with |a| > ``limit`` among neural bonds' known
    activations (NaN if none), and the share per neuron [B] (NaN for non-neural bonds)."""
    act = np.asarray(act, np.float64).reshape(-1, len(neural))
    neural = np.asarray(neural, bool)
    known = np.isfinite(act) & neural[None, :]
    sat = (np.abs(np.where(known, act, 0.0)) > limit) & known
    per = np.full(len(neural), np.nan)
    counts = known.sum(axis=0)
    per[counts > 0] = sat.sum(axis=0)[counts > 0] / counts[counts > 0]
    total = known.sum()
    return (float(sat.sum() / total) if total else float("nan")), per


def neural_weights(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Input weights of the neural bonds: length weights [B, B], rate weights [B, B] (NaN on
    the unused diagonal and in rows of non-neural bonds) and each row's weight range [B]."""
    p, topo = model.params, model.topology
    _, neural = neural_bonds(topo)
    n_b = len(neural)
    w_len = np.full((n_b, n_b), np.nan)
    w_rate = np.full((n_b, n_b), np.nan)
    span = np.full(n_b, np.nan)
    start = 0
    for k in neural_kinds(topo):
        kind = bonds.get(k)
        n = topo.count(k)
        block = slice(start, start + n)
        for par in kind.parameters:
            if par.form != "weights":
                continue
            target = w_len if par.part == "length" else w_rate
            target[block, block] = np.array(p.bonds[k][par.field], np.float64).reshape(n, n)
            for i, b in enumerate(bond for bond in model.spec.bond if bond.kind == k):
                w = getattr(b, par.key)
                if w is not None and (par.when is None or getattr(b, par.when)):
                    span[start + i] = w.max - w.min
        start += n
    unused = np.eye(n_b, dtype=bool) | ~neural[:, None]
    w_len[unused] = np.nan
    w_rate[unused] = np.nan
    return w_len, w_rate, span


def near_zero_share(model: Model, fraction: float = NEAR_ZERO) -> float:
    """Share of neural input weights with |w| < ``fraction`` x (max - min) of their bond's
    weight bounds (NaN for a model without neural inputs)."""
    w_len, w_rate, span = neural_weights(model)
    w = np.stack([w_len, w_rate])  # [2, B, B]
    known = np.isfinite(w)
    if not known.any():
        return float("nan")
    small = np.abs(np.where(known, w, 0.0)) < fraction * span[None, :, None]
    return float((small & known).sum() / known.sum())


@dataclass(frozen=True, eq=False)
class Prediction:
    """A model's predictions along a recording (SI units, NaN where unknown).

    Frames ``[0, fit_frames)`` are the fitted window; later frames (if any) test
    generalisation."""

    names: tuple[str, ...]  # particle names
    markers: tuple[str, ...]
    bonds: np.ndarray  # [B, 2] particle indices of the binary bonds (neural_bonds)
    neural: np.ndarray  # [B] bool
    times: np.ndarray  # [F] seconds from the first frame
    dt: float
    fit_frames: int
    recorded: np.ndarray  # [F, P, D]
    one_step: np.ndarray  # [F, P, D]
    free_run: np.ndarray  # [F, P, D]
    activation: np.ndarray  # [F, B] along the free run
    one_step_rms_mm: np.ndarray  # [P] over the fitted window
    free_run_rms_mm: np.ndarray  # [P] over the fitted window
    one_step_rms_mm_beyond: np.ndarray | None  # [P] beyond the fitted window
    free_run_rms_mm_beyond: np.ndarray | None
    saturated_share: float  # NaN without neurons
    saturated_per_neuron: np.ndarray  # [B]
    near_zero_weight_share: float  # NaN without neural weights
    diverged_at: int | None  # first frame where the free run went non-finite (its RMS: inf)

    @property
    def n_frames(self) -> int:
        return int(self.recorded.shape[0])

    @property
    def extended(self) -> bool:
        return self.n_frames > self.fit_frames


@float64
def predict(
    model: Model,
    traj: Trajectory,
    *,
    fit_frames: int | None = None,
    substeps: int = 1,
    method: str = "euler",
) -> Prediction:
    """One-step and free-run predictions of ``model`` along ``traj`` (markers already in the
    model's particle order). ``fit_frames``: length of the fitted window at the start of
    ``traj`` (default: all of it)."""
    if traj.n_markers != model.topology.n_particles:
        raise ValueError(
            f"{traj.n_markers} markers for a model of {model.topology.n_particles} particles"
        )
    rec = np.asarray(traj.positions, np.float64)
    n = rec.shape[0]
    fit = n if fit_frames is None else max(1, min(int(fit_frames), n))
    dt = traj.dt
    one = one_step(model, rec, dt, substeps, method)
    xs, vs = free_run(model, rec, dt, n, substeps, method)
    act = activations(model, xs, vs, dt)
    pairs_of_bonds, neural = neural_bonds(model.topology)
    sat, per = saturation_share(act, neural)
    complete = np.isfinite(rec).all(axis=(1, 2))
    pairs = complete[1:] & complete[:-1]
    first_run = int(np.argmax(pairs)) + 1 if pairs.any() else n
    # predictions that should exist but went non-finite count as infinite errors
    free_failed = (np.arange(n) > first_run) & ~np.isfinite(xs).all(axis=(1, 2))
    diverged = int(np.argmax(free_failed)) if free_failed.any() else None
    one_failed = np.zeros(n, bool)
    one_failed[2:] = pairs[:-1] & ~np.isfinite(one[2:]).all(axis=(1, 2))
    free_pred = _model_only(xs, first_run)

    def one_rms(lo, hi):
        return _counted_rms(one, rec, lo, hi, one_failed)

    def free_rms(lo, hi):
        return _counted_rms(free_pred, rec, lo, hi, free_failed)

    return Prediction(
        names=model.particle_names,
        markers=tuple(traj.markers),
        bonds=pairs_of_bonds,
        neural=neural,
        times=np.arange(n) * dt,
        dt=dt,
        fit_frames=fit,
        recorded=rec,
        one_step=one,
        free_run=xs,
        activation=act,
        one_step_rms_mm=one_rms(0, fit),
        free_run_rms_mm=free_rms(0, fit),
        one_step_rms_mm_beyond=one_rms(fit, n) if n > fit else None,
        free_run_rms_mm_beyond=free_rms(fit, n) if n > fit else None,
        saturated_share=sat,
        saturated_per_neuron=per,
        near_zero_weight_share=near_zero_share(model),
        diverged_at=diverged,
    )


def _counted_rms(pred, rec, lo: int, hi: int, failed: np.ndarray) -> np.ndarray:
    """RMS over frames [lo, hi); a particle with a recorded target at a failed (non-finite)
    prediction gets +inf, as in the cost."""
    out = rms_mm(pred, rec, slice(lo, hi))
    known = np.isfinite(rec[lo:hi]).all(axis=-1)  # [f, P]
    out[(failed[lo:hi, None] & known).any(axis=0)] = np.inf
    return out


def _model_only(xs: np.ndarray, first_run: int) -> np.ndarray:
    """The free run without its copied start frames (they are not predictions)."""
    out = xs.copy()
    out[: first_run + 1] = np.nan
    return out


def default_frames(record: RunRecord) -> int:
    """Default length of the window shown in a report: twice the fitted window."""
    return 2 * record.window.n_frames


@float64
def predict_run(
    run: str | Path | RunRecord, frames: int | None = None
) -> tuple[Prediction, RunRecord]:
    """Predictions of a run's best model along its fitted window, extended to ``frames``
    frames of the original recording when it is still there and unchanged (``frames`` <= the
    window's length or None: the fitted window only)."""
    record = run if isinstance(run, RunRecord) else load_run(run)
    traj = record.window
    if frames is not None and frames > record.window.n_frames:
        traj = original_window(record, frames) or record.window
    s = record.settings
    pred = predict(
        record.model,
        traj,
        fit_frames=record.window.n_frames,
        substeps=s.substeps,
        method=s.integrator,
    )
    return pred, record
