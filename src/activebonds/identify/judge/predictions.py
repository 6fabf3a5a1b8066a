"""THE module of every prediction from recorded states: the model's and zero force's.

Every model prediction is one compiled program, :func:`runs_from`: from each recorded state
(frames s - 1 and s) the model runs K frames on its own, with the velocity the integrator
carries at s given ``x[s-1]`` and ``x[s]``
(:func:`~activebonds.physics.integrate.start_velocity`; the backward difference for
one-substep Euler), as the cost predicts (DESIGN.md §3). The one-step predictions
(:func:`one_step`) are K = 1 from every frame, the frames ahead (:func:`model_ahead`) K from
every start, a free run (:func:`free_run`) the whole window from the first two complete
frames, never looking at the data again. Zero force's predictions are one formula,
:func:`constant_velocity` (:func:`zero_force_predictions`, :func:`zero_force_ahead`; the fit
cost's and the gait's runs call it too). Everything is float64 NumPy; NaN marks what cannot
be predicted (missing inputs, before the start, or after a free run went non-finite).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ... import bonds
from ...model import Model, Params, Topology
from ...physics import phase, rollout_states, start_velocity
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


@partial(jax.jit, static_argnames=("topo", "n_steps", "substeps", "method", "newton", "last"))
def _runs(
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
    last: bool = False,
):
    """THE program of every prediction from recorded states: from each start (the recorded
    positions ``x_prev`` and ``x0`` [S, P, D] of its frames s - 1 and s, ``t0`` [S] the time
    of s) the model runs ``n_steps`` frames on its own. Returns (start velocities [S, P, D],
    positions, velocities[, phases]) of the runs [S, n_steps, ...], or with ``last`` only
    their last positions [S, P, D]. ``psis``: an entrained drive's phases at the frames of
    ``x_prev`` and ``x0`` ([S] each); ``newton``: the start velocities by Newton's method
    (see :func:`solved`). One start without its axis ([P, D], a scalar time) is run as it
    is, not vmapped: a time-dependent force's sines then take their scalar form, as a free
    run always has."""

    def one(a, b, t, *psi):
        p_prev, p0 = psi if psi else (None, None)
        v = start_velocity(
            params, topo.topo, a, b, dt, substeps, method, t=t, psi=p_prev, newton=newton
        )
        run = rollout_states(params, topo.topo, b, v, dt, n_steps, substeps, method, t, p0)
        return (v, run[0][-1]) if last else (v, *run)

    if x0.ndim == 2:  # one start [P, D], run as it is
        return one(x_prev, x0, t0, *(psis or ()))
    return jax.vmap(one)(x_prev, x0, t0, *(psis or ()))


def runs_from(
    model: Model,
    x_prev: np.ndarray,
    x0: np.ndarray,
    times: np.ndarray,
    dt: float,
    n_steps: int,
    substeps: int = 1,
    method: str = "euler",
    psis: tuple[np.ndarray, np.ndarray] | None = None,
    last: bool = False,
) -> tuple:
    """The model run ``n_steps`` frames from each recorded state: the positions ``x_prev``
    and ``x0`` [S, P, D] of frames s - 1 and s, ``times`` [S] the times of s, ``psis`` an
    entrained drive's phases there (or None); one state without the start axis is one run
    (:func:`_runs`). Every prediction of this module is one call
    of it (one compiled program per shape): the one-step predictions (one frame from every
    frame), the frames ahead (K frames from every start), a free run (the whole window from
    one start). Returns float64 arrays: (start velocities [S, P, D], positions, velocities[,
    phases]) [S, n_steps, ...], or with ``last`` (start velocities, last positions
    [S, P, D])."""
    out = solved(
        _runs,
        float64_params(model),
        jnp.asarray(x_prev),
        jnp.asarray(x0),
        jnp.asarray(times),
        float(dt),
        topo=StaticTopology(model.topology),
        n_steps=int(n_steps),
        substeps=int(substeps),
        method=method,
        psis=None if psis is None else tuple(jnp.asarray(p) for p in psis),
        last=last,
    )
    return tuple(np.array(a, dtype=np.float64) for a in out)


@partial(jax.jit, static_argnames=("topo", "substeps"))
def _track(params, s, dt, topo: StaticTopology, substeps: int):
    return phase.track(params, topo.topo, s, dt, substeps)


@float64
def tracked_phases(
    model: Model,
    positions: np.ndarray,
    dt: float,
    substeps: int = 1,
    offset: int = 0,
    before: np.ndarray | None = None,
) -> np.ndarray | None:
    """An entrained drive's phase at every frame [F] of a recording, tracked along its
    signal (:func:`~activebonds.physics.phase.track`) from the start phase at the model's
    time origin, ``offset`` frames before the recording's first frame; None without one.
    The frames before the signal's marker is first recorded (the ``offset`` frames
    included) get its first period repeated backwards
    (:func:`~activebonds.physics.phase.extended_back`; the period from the signal's
    autocorrelation, else the drive's frequency). ``before``: the recorded positions of
    those ``offset`` frames (its last ones count; :func:`before_window`), where the recording
    has them: the phase is tracked along them instead."""
    topo = model.topology
    if not phase.entrained(topo):
        return None
    x = np.asarray(positions, np.float64)
    params = float64_params(model)
    if not np.isfinite(phase.signal(topo, x, np)).any():
        return np.full(x.shape[0], float(np.asarray(phase.start_phase(params, topo))))
    offset = max(int(offset), 0)
    if offset:  # the frames from the model's origin, recorded or not
        x = before_window(x, offset, before)
    s = phase.recorded_signal(topo, x, period=phase.period_frames(params, topo, dt))
    psi = np.asarray(_track(params, jnp.asarray(s), float(dt), StaticTopology(topo), substeps))
    return psi[offset:]


def before_window(x: np.ndarray, offset: int, before: np.ndarray | None = None) -> np.ndarray:
    """Positions ``x`` [F, P, D] with the ``offset`` frames before them prepended: the last
    ``offset`` frames of ``before`` where given (the recording from the model's time origin),
    NaN for any it does not have."""
    x = np.asarray(x, np.float64)
    pad = np.full((max(int(offset), 0), *x.shape[1:]), np.nan)
    if before is not None and pad.shape[0]:
        b = np.asarray(before, np.float64)[-pad.shape[0] :]
        pad[pad.shape[0] - b.shape[0] :] = b
    return np.concatenate([pad, x])


@float64
def one_step(
    model: Model,
    positions: np.ndarray,
    dt: float,
    substeps: int = 1,
    method: str = "euler",
    offset: int = 0,
    before: np.ndarray | None = None,
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
    psi = tracked_phases(model, x, dt, substeps, offset, before)
    psis = None if psi is None else (psi[:-2], psi[1:-1])
    times = (np.arange(1, x.shape[0] - 1) + max(int(offset), 0)) * float(dt)
    pred = runs_from(model, x_prev, x0, times, dt, 1, substeps, method, psis, last=True)[1]
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
    before: np.ndarray | None = None,
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
        phases = tracked_phases(model, x, dt, substeps, offset, before)
    psis = None
    if phases is not None:
        psis = (phases[s - 1], phases[s])
        psi_out[: s + 1] = phases[: s + 1]
    t0 = (s + max(int(offset), 0)) * float(dt)
    steps = max(n - s - 1, 1)
    run = runs_from(model, x[s - 1], x[s], t0, dt, steps, substeps, method, psis)
    vs[s] = run[0]
    if n - s - 1 > 0:
        xs[s + 1 :] = run[1]
        vs[s + 1 :] = run[2]
        if psis is not None:
            psi_out[s + 1 :] = run[3][: n - s - 1]
    bad = ~(np.isfinite(xs).all(axis=(1, 2)) & np.isfinite(vs).all(axis=(1, 2)))
    bad[: s + 1] = False
    if bad.any():
        first = int(np.argmax(bad))
        xs[first:] = np.nan
        vs[first:] = np.nan
        psi_out[first:] = np.nan
    return (xs, vs, psi_out) if with_phases else (xs, vs)


def ahead_starts(positions: np.ndarray, k: int) -> np.ndarray:
    """Start frames s with frames s - 1 and s complete and a frame s + k in the window."""
    complete = np.isfinite(positions).all(axis=(1, 2))
    s = np.arange(1, positions.shape[0] - k)
    return s[complete[s] & complete[s - 1]] if s.size else s


def ahead_terms(positions: np.ndarray, k: int, reach: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(start frames s [S], which particles' predictions of s + k count there [S, P]): a
    particle's counts where every particle ``reach`` [P, P] says can move it within k frames
    (itself among them) is recorded at s - 1 and s, as the fit's windows count them
    (:func:`~activebonds.identify.costs.windows.make_windows`); the starts, those where one
    counts. With every frame complete, :func:`ahead_starts` with every particle."""
    present = np.isfinite(positions).all(axis=-1)  # [F, P]
    s = np.arange(1, positions.shape[0] - k)
    both = present[s] & present[s - 1]  # [S, P]
    counts = ~((~both).astype(np.int64) @ np.asarray(reach, np.int64).T > 0)
    keep = counts.any(axis=1)
    return s[keep], counts[keep]


def _inputs(rec: np.ndarray, k: int, terms) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """(starts, counts or None, the positions to start from): ``terms`` as given (starts,
    counts, positions with the missing samples filled), else :func:`ahead_starts` on the
    recording as it is."""
    if terms is None:
        return ahead_starts(rec, k), None, rec
    starts, counts, filled = terms
    return np.asarray(starts), np.asarray(counts, bool), np.asarray(filled, np.float64)


@float64
def model_ahead(
    model: Model,
    positions: np.ndarray,
    dt: float,
    k: int,
    substeps: int = 1,
    method: str = "euler",
    offset: int = 0,
    before: np.ndarray | None = None,
    terms: tuple | None = None,
) -> np.ndarray:
    """The model's prediction of each frame ``s + k`` from the recorded state at ``s``
    (:func:`ahead_starts`; ``terms``: (starts, which particles count at each [S, P], the
    positions with the missing samples filled), :func:`ahead_terms`' rule), aligned with the
    recording [F, P, D]: NaN where there is no start or term (and +inf where the run went
    non-finite). Time and an entrained drive's phase as :func:`one_step`'s."""
    rec = np.asarray(positions, np.float64)
    out = np.full_like(rec, np.nan)
    starts, counts, x = _inputs(rec, k, terms)
    if starts.size == 0:
        return out
    psi = tracked_phases(model, rec, dt, substeps, offset, before)  # entrained, else None
    psis = None if psi is None else (psi[starts - 1], psi[starts])
    times = (starts + int(offset)) * float(dt)
    pred = runs_from(
        model, x[starts - 1], x[starts], times, dt, k, substeps, method, psis, last=True
    )[1]
    pred[~np.isfinite(pred)] = np.inf  # a failed prediction: an infinite error, not a gap
    if counts is not None:
        pred[~counts] = np.nan
    out[starts + k] = pred
    return out


# ----------------------------------------------------------------------------- zero force


def constant_velocity(x, v, t):
    """THE zero-force (constant-velocity) prediction: positions ``x`` carried on at the
    velocity ``v`` for the time ``t``, ``x + t v`` (broadcast; ``v`` per frame and ``t`` in
    frames, or per second and in seconds, as the fit cost's start velocities)."""
    return x + t * v


def zero_force_ahead(positions: np.ndarray, k: int, terms: tuple | None = None) -> np.ndarray:
    """The zero-force prediction of each frame ``s + k`` from frames ``s - 1`` and ``s``
    (:func:`ahead_starts`, or a model's ``terms`` as :func:`model_ahead` takes them),
    ``x_s + k (x_s - x_{s-1})``, [F, P, D] (NaN where there is no start or term)."""
    rec = np.asarray(positions, np.float64)
    out = np.full_like(rec, np.nan)
    starts, counts, _ = _inputs(rec, k, terms)
    pred = constant_velocity(rec[starts], rec[starts] - rec[starts - 1], k)
    if counts is not None:  # the model's terms, for a comparison on the same ones
        pred[~counts] = np.nan
    out[starts + k] = pred
    return out


def zero_force_predictions(positions: np.ndarray, start: int) -> tuple[np.ndarray, np.ndarray]:
    """The zero-force predictor's one-step predictions [F, P, D] (NaN for frames 0 and 1
    and where an input frame is incomplete, as the model's) and its free run from frames
    ``start - 1`` and ``start`` (NaN up to ``start``), the predictions of
    :func:`~activebonds.identify.judge.metrics.zero_force_metrics`."""
    rec = np.asarray(positions, np.float64)
    one = np.full_like(rec, np.nan)
    one[2:] = 2.0 * rec[1:-1] - rec[:-2]
    complete = np.isfinite(rec).all(axis=(1, 2))
    one[2:][~(complete[1:-1] & complete[:-2])] = np.nan  # the terms the metrics count
    run = np.full_like(rec, np.nan)
    if 1 <= start < rec.shape[0]:  # else no start (no two complete frames): no free run
        steps = np.arange(1, rec.shape[0] - start, dtype=np.float64)[:, None, None]
        run[start + 1 :] = constant_velocity(rec[start], rec[start] - rec[start - 1], steps)
    return one, run


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
