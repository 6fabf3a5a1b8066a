"""What a model predicts along a recording: one-step predictions, a free run, their errors.

One-step predictions are made as the cost makes them (DESIGN.md §3): frame t is predicted
from the *recorded* state at t - 1, with the velocity the integrator carries there given
``x[t-2]`` and ``x[t-1]`` (:func:`~activebonds.physics.integrate.start_velocity`; the
backward difference for one-substep Euler). The free run starts from the first two recorded frames and never
looks at the data again. Everything is float64 NumPy; NaN marks what cannot be predicted
(missing inputs, before the start, or after a free run went non-finite).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ... import bonds
from ...model import Model, Params, Topology
from ...physics import advance, phase, rollout_states, start_velocity
from ...physics.integrators import Integrator
from ...runtime import float64


class StaticTopology:
    """A topology as a static jit argument, equal by content: compiled predictions are reused
    across models of the same shape (e.g. the runs of a series)."""

    def __init__(self, topo: Topology):
        self.topo = topo
        self.key = (
            topo.n_particles,
            topo.dimension,
            tuple(sorted(topo.disabled)),
            getattr(topo, "drive", None),
            *(
                (kind, name, a.shape, a.tobytes())
                for kind, arrays in topo.bonds.items()
                for name, a in arrays.items()
            ),
        )

    def __hash__(self) -> int:
        return hash(self.key)

    def __eq__(self, other) -> bool:
        return isinstance(other, StaticTopology) and other.key == self.key


def float64_params(model: Model) -> Params:
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


def solved(program, *args, **kwargs):
    """``program(*args, **kwargs)`` (its first output the start velocities) with the start
    velocities by the fixed point (cheap), run again with Newton's method where one is not
    finite: the fixed point fails where the damping is strong for the frame interval
    (:func:`~activebonds.physics.integrate.start_velocity`). A run that diverges after its
    start is not run again."""
    out = program(*args, **kwargs)
    if Integrator(kwargs["method"], kwargs["substeps"]).exact_backward:
        return out
    if np.isfinite(np.asarray(out[0])).all():
        return out
    return program(*args, newton=True, **kwargs)


@partial(jax.jit, static_argnames=("topo", "substeps", "method", "newton"))
def _one_step(
    params,
    x_prev,
    x0,
    times,
    dt,
    topo: StaticTopology,
    substeps: int,
    method: str,
    psis=None,
    newton: bool = False,
):
    """(start velocities, predictions): ``psis``, an entrained drive's phases (at the frames of
    ``x_prev``, of ``x0``); ``newton``, the start velocities by Newton's method (see
    :func:`solved`)."""

    def step(a, b, t, *psi):
        v = start_velocity(
            params,
            topo.topo,
            a,
            b,
            dt,
            substeps,
            method,
            t=t,
            psi=psi[0] if psi else None,
            newton=newton,
        )
        return v, advance(params, topo.topo, b, v, dt, substeps, method, t, *psi[1:])[0]

    return jax.vmap(step)(x_prev, x0, times, *(psis or ()))


@partial(jax.jit, static_argnames=("topo", "n_steps", "substeps", "method", "newton"))
def _free_run(
    params,
    x_prev,
    x0,
    t0,
    dt,
    topo: StaticTopology,
    n_steps: int,
    substeps: int,
    method: str,
    psis=None,
    newton: bool = False,
):
    """``psis``: an entrained drive's phases at the frames of ``x_prev`` and ``x0``; then the
    run's phases are returned too. ``newton``: as :func:`_one_step`'s."""
    psi_prev, psi0 = psis if psis is not None else (None, None)
    v0 = start_velocity(
        params, topo.topo, x_prev, x0, dt, substeps, method, t=t0, psi=psi_prev, newton=newton
    )
    run = rollout_states(params, topo.topo, x0, v0, dt, n_steps, substeps, method, t0, psi0)
    return (v0, *run)


@partial(jax.jit, static_argnames=("topo", "substeps"))
def _track(params, s, dt, topo: StaticTopology, substeps: int):
    return phase.track(params, topo.topo, s, dt, substeps)


@float64
def tracked_phases(
    model: Model, positions: np.ndarray, dt: float, substeps: int = 1, offset: int = 0
) -> np.ndarray | None:
    """An entrained drive's phase at every frame [F] of a recording, tracked along its
    signal (:func:`~activebonds.physics.phase.track`) from the start phase at the model's
    time origin, ``offset`` frames before the recording's first frame; None without one.
    The frames before the signal's marker is first recorded (the ``offset`` frames
    included) get its first period repeated backwards
    (:func:`~activebonds.physics.phase.extended_back`; the period from the signal's
    autocorrelation, else the drive's frequency)."""
    topo = model.topology
    if not phase.entrained(topo):
        return None
    x = np.asarray(positions, np.float64)
    params = float64_params(model)
    if not np.isfinite(phase.signal(topo, x, np)).any():
        return np.full(x.shape[0], float(np.asarray(phase.start_phase(params, topo))))
    offset = max(int(offset), 0)
    if offset:  # the frames from the model's origin, unrecorded here
        x = np.concatenate([np.full((offset, *x.shape[1:]), np.nan), x])
    s = phase.recorded_signal(topo, x, period=phase.period_frames(params, topo, dt))
    psi = np.asarray(_track(params, jnp.asarray(s), float(dt), StaticTopology(topo), substeps))
    return psi[offset:]


@float64
def one_step(
    model: Model,
    positions: np.ndarray,
    dt: float,
    substeps: int = 1,
    method: str = "euler",
    offset: int = 0,
) -> np.ndarray:
    """Prediction of every frame t >= 2 from the recorded frames t - 1 and t - 2, [F, P, D].

    NaN where an input frame misses a marker, and for frames 0 and 1. Time is 0 at frame 0
    (the fitted window's first frame), or ``offset`` frames before it; an entrained drive's
    phase is tracked along the recording from there (:func:`tracked_phases`)."""
    x = np.asarray(positions, dtype=np.float64)
    out = np.full_like(x, np.nan)
    if x.shape[0] < 3:
        return out
    prev, prev2 = x[1:-1], x[:-2]
    ok = np.isfinite(prev).all(axis=(1, 2)) & np.isfinite(prev2).all(axis=(1, 2))
    x0 = np.where(ok[:, None, None], prev, 0.0)
    x_prev = np.where(ok[:, None, None], prev2, 0.0)
    psi = tracked_phases(model, x, dt, substeps, offset)
    psis = None if psi is None else (jnp.asarray(psi[:-2]), jnp.asarray(psi[1:-1]))
    pred = solved(
        _one_step,
        float64_params(model),
        jnp.asarray(x_prev),
        jnp.asarray(x0),
        (jnp.arange(1, x.shape[0] - 1) + max(int(offset), 0)) * float(dt),
        float(dt),
        topo=StaticTopology(model.topology),
        substeps=int(substeps),
        method=method,
        psis=psis,
    )[1]
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
    phases: np.ndarray | None = None,
    with_phases: bool = False,
    offset: int = 0,
) -> tuple[np.ndarray, ...]:
    """Free run from the first two complete consecutive recorded frames.

    Returns positions and velocities [n_frames, P, D] (velocities are the model's own state;
    frames before the start are the recording and NaN velocities). Once a frame goes
    non-finite, it and every later frame are NaN. An entrained drive starts with its phase
    tracked along ``positions`` (:func:`tracked_phases`; time 0 ``offset`` frames before
    the first frame, as :func:`one_step`'s), or at ``phases`` [F] when given
    (e.g. tracked along a recording whose frames before the start are hidden here); with
    ``with_phases``, the run's phases [n_frames] are returned too (NaN where unknown; the
    tracked ones up to the start)."""
    x = np.asarray(positions, dtype=np.float64)
    n = x.shape[0] if n_frames is None else int(n_frames)
    xs = np.full((n, *x.shape[1:]), np.nan)
    vs = np.full_like(xs, np.nan)
    psi_out = np.full(n, np.nan)
    complete = np.isfinite(x).all(axis=(1, 2))
    starts = np.flatnonzero(complete[1:] & complete[:-1]) + 1
    if starts.size == 0 or starts[0] >= n:
        return (xs, vs, psi_out) if with_phases else (xs, vs)
    s = int(starts[0])
    xs[: s + 1] = x[: s + 1]
    if phases is None:
        phases = tracked_phases(model, x, dt, substeps, offset)
    psis = None
    if phases is not None:
        psis = (jnp.asarray(phases[s - 1]), jnp.asarray(phases[s]))
        psi_out[: s + 1] = phases[: s + 1]
    run = solved(
        _free_run,
        float64_params(model),
        jnp.asarray(x[s - 1]),
        jnp.asarray(x[s]),
        (s + max(int(offset), 0)) * float(dt),
        float(dt),
        topo=StaticTopology(model.topology),
        n_steps=max(n - s - 1, 1),
        substeps=int(substeps),
        method=method,
        psis=psis,
    )
    vs[s] = np.asarray(run[0], dtype=np.float64)
    if n - s - 1 > 0:
        xs[s + 1 :] = np.array(run[1], dtype=np.float64)
        vs[s + 1 :] = np.asarray(run[2], dtype=np.float64)
        if psis is not None:
            psi_out[s + 1 :] = np.asarray(run[3], dtype=np.float64)[: n - s - 1]
    bad = ~(np.isfinite(xs).all(axis=(1, 2)) & np.isfinite(vs).all(axis=(1, 2)))
    bad[: s + 1] = False
    if bad.any():
        first = int(np.argmax(bad))
        xs[first:] = np.nan
        vs[first:] = np.nan
        psi_out[first:] = np.nan
    return (xs, vs, psi_out) if with_phases else (xs, vs)


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
