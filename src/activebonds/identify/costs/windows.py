"""The short-term cost of the paper (§3.2), with local costs per particle and a horizon H.

DESIGN.md §3: velocities come from the two recorded positions before a start (the backward
difference ``(x_t - x_{t-1}) / dt``, made consistent with the integrator and substep count by
:func:`~activebonds.physics.integrate.start_velocity`), so a prediction never sees the frame it
predicts. From the *real* state at a start frame s, the model
is integrated H steps; every predicted position is compared with the recorded one. Starts are
s = 1, 1 + H, 1 + 2H, ... so H = 1 is the paper's one-step cost and H = window length a free run.
The local cost of particle p is its own share; the global cost is their sum. A prediction whose
inputs or target are missing contributes nothing: without a model's bond graph (``neighbours``
None) its inputs are every particle at s and s - 1; with it (:func:`neighbours_of`), only the
particles that can act on p before the target (:func:`_terms`), so a recording whose markers
are seldom all present together still gives most of its samples. Each restart
knows its time, ``s * dt`` from the window's first frame, for forces that depend on time (a
unary bond's moving anchor); a model whose drive is entrained starts each restart with the
drive's phase tracked along the record (:func:`start_phases`).
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ...data.smoothing import smooth_positions
from ...model.model import Model
from ...physics import phase
from ...physics.integrate import (
    START_ITERATIONS,
    START_TOLERANCE,
    advance,
    rollout_states,
    start_velocity,
    stiff,
)
from ...physics.integrators import Integrator


@dataclass(frozen=True, eq=False)
class Windows:
    """Restart states and targets cut from a recorded trajectory (NumPy, float64)."""

    x0: np.ndarray  # [S, P, D] real positions at each start
    x_prev: np.ndarray  # [S, P, D] real positions one frame before each start
    v0: np.ndarray  # [S, P, D] backward-difference velocities at each start
    target: np.ndarray  # [S, H, P, D] recorded positions to predict (0 where missing)
    weight: np.ndarray  # [S, H, P] 1.0 where the term counts
    dt: float
    t0: np.ndarray | None = None  # [S] time of each start (s * dt, from the first frame)
    # the recordings themselves (positions [F, P, D], NaN where missing), and each start's
    # frame and recording: an entrained drive's phase is tracked along them
    records: tuple[np.ndarray, ...] = ()
    frames: np.ndarray | None = None  # [S] each start's frame in its recording
    recording: np.ndarray | None = None  # [S] the index of its recording in ``records``

    @property
    def times(self) -> np.ndarray:
        """[S] the time of each start (s), zeros where none was given."""
        if self.t0 is None:
            return np.zeros(self.x0.shape[0])
        return np.asarray(self.t0, np.float64)

    @property
    def n_terms(self) -> int:
        return int(self.weight.sum())

    @property
    def horizon(self) -> int:
        return int(self.target.shape[1])


def neighbours_of(model) -> np.ndarray:
    """[P, P] bool of a :class:`~activebonds.model.Model` (or its
    :class:`~activebonds.model.params.Topology`): ``[p, q]`` True where particle q (q != p)
    can exert a force on p, i.e. q shares a bond of an active kind with p (a binary bond's
    other end, a ternary bond's two others). Unary bonds, ground contacts, periodic forces and
    the uniform field act on one particle and add nothing; a disabled kind neither."""
    topo = getattr(model, "topology", model)
    n = topo.n_particles
    out = np.zeros((n, n), bool)
    for kind in topo.active():
        members = np.asarray(topo.particles(kind))
        if members.ndim != 2 or members.shape[1] < 2:
            continue
        for a in range(members.shape[1]):
            for b in range(members.shape[1]):
                if a != b:
                    out[members[:, a], members[:, b]] = True
    np.fill_diagonal(out, False)
    return out


def fill_missing(positions: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Positions [F, P, D] with each particle's missing samples filled: linear in time
    between its recorded samples, held before its first and after its last (0 for a particle
    never recorded). Finite everywhere, so that forces computed from a restart state with a
    missing particle stay finite; no term that reads a filled value counts."""
    out = np.where(mask[..., None], positions, 0.0).astype(np.float64)
    frames = np.arange(positions.shape[0])
    for p in range(positions.shape[1]):
        seen = mask[:, p]
        if seen.all() or not seen.any():
            continue
        for c in range(positions.shape[2]):
            out[~seen, p, c] = np.interp(frames[~seen], frames[seen], positions[seen, p, c])
    return out


def make_windows(
    positions: np.ndarray,
    mask: np.ndarray,
    dt: float,
    horizon: int = 1,
    smooth: int = 0,
    neighbours: np.ndarray | None = None,
) -> Windows:
    """Cut restart windows from positions [F, P, D] (NaN where missing) and mask [F, P].

    ``smooth``: a Savitzky-Golay window (frames; 0: off) applied to the restart states only
    (the positions at and one frame before each start, hence the velocities), never to the
    targets: see :mod:`activebonds.data.smoothing`. ``neighbours``: the model's [P, P] who
    acts on whom (:func:`neighbours_of`); a prediction then needs only the particles that
    can act on it present at the start (:func:`_terms`); None: every particle. The restart
    states' missing samples are filled (:func:`fill_missing`; they count in no term)."""
    n_frames = positions.shape[0]
    if n_frames < 3:
        raise ValueError("the cost needs at least 3 frames (two to start, one to predict)")
    horizon = max(1, min(int(horizon), n_frames - 2))
    x = np.where(mask[..., None], positions, 0.0)
    inputs = positions
    if smooth:
        inputs = smooth_positions(positions, mask, smooth)
    inputs = fill_missing(inputs, mask)
    starts, frames_c, weight, _ = _terms(mask, horizon, neighbours)
    x0 = inputs[starts]
    v0 = (inputs[starts] - inputs[starts - 1]) / dt
    target = x[frames_c]
    return Windows(
        x0=x0,
        x_prev=inputs[starts - 1],
        v0=v0,
        target=target,
        weight=weight,
        dt=float(dt),
        t0=starts * float(dt),
        records=(np.where(mask[..., None], positions, np.nan),),
        frames=starts,
        recording=np.zeros(len(starts), np.int64),
    )


def reach_of(neighbours: np.ndarray, hops: int) -> np.ndarray:
    """[P, P] bool: ``[p, q]`` where q is p or within ``hops`` bonds of it."""
    return _reach(neighbours, max(int(hops), 1))[-1]


def _reach(neighbours: np.ndarray, horizon: int) -> list[np.ndarray]:
    """[R_1, ..., R_H], R_k [P, P] bool: ``R_k[p, q]`` where q is p or within k bonds of it
    (the particles whose start state can move p within k frames of one Euler substep)."""
    n = np.asarray(neighbours, bool)
    if n.ndim != 2 or n.shape[0] != n.shape[1]:
        raise ValueError(f"neighbours must be a [P, P] matrix, not {n.shape}")
    step = n | np.eye(n.shape[0], dtype=bool)
    out = [step]
    for _ in range(horizon - 1):
        out.append((out[-1].astype(np.int64) @ step.astype(np.int64)) > 0)
    return out


def _terms(mask: np.ndarray, horizon: int, neighbours: np.ndarray | None = None):
    """(starts [S], target frames [S, H] clipped to the window, weight [S, H, P] float, the
    terms inside the window [S, H] bool) of :func:`make_windows`: the prediction of particle p
    at frame s + k (1 <= k <= H) from start s counts when p is present at s + k (the target)
    and, at both s and s - 1 (the start state):

    * without ``neighbours``: every particle;
    * with ``neighbours`` [P, P] (:func:`neighbours_of`): p and every particle within k bonds
      of p (for k = 1, p's bonded neighbours; none beyond p for a particle held only by
      unary bonds, contacts or the field). One Euler substep moves a particle by the forces
      of its neighbours alone, so the prediction then reads no other particle's start
      state; with several substeps (or a start velocity solved over the frame) particles
      further away enter it at higher order in the frame time, through the filled values
      (:func:`fill_missing`) where they are missing."""
    n_frames, n_p = mask.shape
    starts = np.arange(1, n_frames - 1, horizon)
    frames = starts[:, None] + np.arange(1, horizon + 1)[None, :]  # [S, H]
    inside = frames < n_frames
    frames_c = np.minimum(frames, n_frames - 1)
    if neighbours is None:
        ok_start = mask[starts].all(axis=1) & mask[starts - 1].all(axis=1)
        ok = np.broadcast_to(ok_start[:, None, None], (len(starts), horizon, n_p))
    else:
        if np.shape(neighbours) != (n_p, n_p):
            raise ValueError(f"neighbours {np.shape(neighbours)} for {n_p} particles")
        missing = (~(mask[starts] & mask[starts - 1])).astype(np.int64)  # [S, P]
        ok = np.stack(
            [(missing @ r.T.astype(np.int64)) == 0 for r in _reach(neighbours, horizon)], 1
        )
    weight = (mask[frames_c] & inside[..., None] & ok).astype(np.float64)
    return starts, frames_c, weight, inside


def count_predictions(
    mask: np.ndarray, horizon: int = 1, neighbours: np.ndarray | None = None
) -> tuple[int, int]:
    """(kept, possible): the cost's terms (one predicted particle position each) in a window
    with presence ``mask`` [F, P], and as many as it would hold without gaps; exactly
    :func:`make_windows`'s ``n_terms`` (with the same ``neighbours``) and its count with every
    marker present. NumPy only, nothing compiled: the ``fit`` command checks a window with it
    before it starts."""
    mask = np.asarray(mask, bool)
    n_frames = mask.shape[0]
    if n_frames < 3:
        return 0, 0
    horizon = max(1, min(int(horizon), n_frames - 2))
    _, _, weight, inside = _terms(mask, horizon, neighbours)
    return int(weight.sum()), int(inside.sum()) * mask.shape[1]


def join_windows(parts: list[Windows]) -> Windows:
    """The restart windows of several recordings (one frame rate) as one set; each keeps the
    times of its own recording."""
    if len(parts) == 1:
        return parts[0]
    horizon = max(w.horizon for w in parts)

    def pad(a, w):  # [S, H, ...] -> [S, horizon, ...] with zeros (weight 0: not counted)
        extra = horizon - a.shape[1]
        return np.concatenate([a, np.zeros((a.shape[0], extra, *a.shape[2:]))], axis=1)

    return Windows(
        x0=np.concatenate([w.x0 for w in parts]),
        x_prev=np.concatenate([w.x_prev for w in parts]),
        v0=np.concatenate([w.v0 for w in parts]),
        target=np.concatenate([pad(w.target, w) for w in parts]),
        weight=np.concatenate([pad(w.weight, w) for w in parts]),
        dt=parts[0].dt,
        t0=np.concatenate([w.times for w in parts]),
        **_joined_records(parts),
    )


def _joined_records(parts: list[Windows]) -> dict:
    """The recordings of several windows' sets, each start pointing into its own."""
    if any(w.frames is None for w in parts):
        return {}
    offsets = np.cumsum([0] + [len(w.records) for w in parts[:-1]])
    return {
        "records": tuple(r for w in parts for r in w.records),
        "frames": np.concatenate([w.frames for w in parts]),
        "recording": np.concatenate([w.recording + o for w, o in zip(parts, offsets, strict=True)]),
    }


def start_phases(model: Model, windows: Windows, substeps: int):
    """``params -> (psi at each start's previous frame [S], psi at each start [S])`` of an
    entrained drive, tracked along the recordings from the start phase at each recording's
    first frame (:func:`~activebonds.physics.phase.track`); None for a model without one."""
    topo = model.topology
    if not phase.entrained(topo):
        return None
    if windows.frames is None:
        raise ValueError("an entrained drive needs the windows' recordings to track its phase")
    period = phase.period_frames(model.params, topo, windows.dt)  # (a leading gap's fill)
    signals = [jnp.asarray(phase.recorded_signal(topo, r, period=period)) for r in windows.records]
    frames, which = np.asarray(windows.frames), np.asarray(windows.recording)

    def phases(params):
        out = jnp.zeros(len(frames), signals[0].dtype)
        prev = out
        for i, s in enumerate(signals):
            psi = phase.track(params, topo, s, windows.dt, substeps)
            mine = which == i
            out = out.at[np.flatnonzero(mine)].set(psi[frames[mine]])
            prev = prev.at[np.flatnonzero(mine)].set(psi[np.maximum(frames[mine] - 1, 0)])
        return prev, out

    return phases


def _predictor(
    model: Model,
    windows: Windows,
    substeps: int,
    method: str,
    newton: bool = False,
    unroll: bool = False,
):
    """``params -> predicted positions [S, H, P, D]`` from every restart state; ``newton``:
    the start velocities by Newton's method, else by the fixed point (see
    :func:`~activebonds.physics.integrate.start_velocity`); ``unroll``: the substeps written
    out (a population's cost runs faster so: :func:`~activebonds.physics.integrate.advance`)."""
    topo = model.topology
    x0, v0 = jnp.asarray(windows.x0), jnp.asarray(windows.v0)
    t0 = jnp.asarray(windows.times)
    dt, horizon = windows.dt, windows.horizon
    exact_backward = Integrator(method, substeps).exact_backward  # the start velocity is v0
    phases = start_phases(model, windows, substeps)
    if phases is not None:
        return _phased_predictor(model, windows, substeps, method, phases, newton, unroll)

    def velocities(params):
        if exact_backward:
            return v0
        return _start_velocities(params, topo, windows, substeps, method, newton, unroll)

    def predict(params):
        v = velocities(params)
        if horizon == 1:

            def step(x, v, t):
                return advance(params, topo, x, v, dt, substeps, method, t, unroll=unroll)[0]

            return jax.vmap(step)(x0, v, t0)[:, None]
        run = jax.vmap(
            lambda x, v, t: rollout_states(
                params, topo, x, v, dt, horizon, substeps, method, t, unroll=unroll
            )[0]
        )
        return run(x0, v, t0)

    return predict


def _start_velocities(params, topo, windows, substeps, method, newton, unroll, psi=None):
    """Every restart's start velocity (:func:`~activebonds.physics.integrate.start_velocity`,
    vmapped over the restarts), with an entrained drive's phases ``psi`` at the frames
    before them."""

    def one(a, b, t, *p):
        return start_velocity(
            params,
            topo,
            a,
            b,
            windows.dt,
            substeps,
            method,
            START_ITERATIONS,
            t,
            psi=p[0] if p else None,
            newton=newton,
            unroll=unroll,
        )

    args = (jnp.asarray(windows.x_prev), jnp.asarray(windows.x0), jnp.asarray(windows.times))
    return jax.vmap(one)(*args, *(() if psi is None else (psi,)))


def _phased_predictor(
    model: Model,
    windows: Windows,
    substeps: int,
    method: str,
    phases,
    newton: bool = False,
    unroll: bool = False,
):
    """:func:`_predictor` for an entrained drive: each restart starts from its recorded
    state with the phase tracked along the record there (:func:`start_phases`); the phase
    then moves with the predicted state."""
    topo = model.topology
    x0, v0 = jnp.asarray(windows.x0), jnp.asarray(windows.v0)
    t0 = jnp.asarray(windows.times)
    dt, horizon = windows.dt, windows.horizon

    def predict(params):
        psi_prev, psi0 = phases(params)
        v = v0
        if not Integrator(method, substeps).exact_backward:
            v = _start_velocities(params, topo, windows, substeps, method, newton, unroll, psi_prev)

        def run(x, v, t, p):
            xs = rollout_states(params, topo, x, v, dt, horizon, substeps, method, t, p, unroll)
            return xs[0]

        return jax.vmap(run)(x0, v, t0, psi0)

    return predict


def make_cost(
    model: Model, windows: Windows, substeps: int = 1, method: str = "euler", unroll: bool = True
):
    """A pure function ``genome -> (global cost, local costs [P])`` for one individual.

    Costs are sums of squared position errors (m^2); a non-finite prediction gives +inf.
    ``unroll``: the substeps written out (the population's cost, vmapped, runs faster so:
    :func:`~activebonds.physics.integrate.advance`).
    """
    layout = model.layout
    target, weight = jnp.asarray(windows.target), jnp.asarray(windows.weight)
    predict = _predictor(model, windows, substeps, method, unroll=unroll)

    def cost(genome):
        params = layout.decode(genome)
        err2 = jnp.sum((predict(params) - target) ** 2, axis=-1)  # [S, H, P]
        local = jnp.sum(jnp.where(weight > 0, err2, 0.0), axis=(0, 1))
        local = jnp.where(jnp.isfinite(local), local, jnp.inf)
        return jnp.sum(local), local

    return cost


def make_residuals(
    model: Model,
    windows: Windows,
    substeps: int = 1,
    method: str = "euler",
    newton: bool = False,
    unroll: bool = False,
):
    """``genome -> residuals [S, H, P, D]`` (m): predicted minus recorded positions, 0 where
    the term does not count. Their sum of squares is :func:`make_cost`'s global cost.
    ``newton``: the start velocities by Newton's method, which converges where the fixed
    point does not (the population's cost then +inf), at a compilation and a Jacobian of the
    landing per start (:func:`~activebonds.physics.integrate.start_velocity`). ``unroll``:
    the substeps written out (:func:`~activebonds.physics.integrate.advance`)."""
    layout = model.layout
    target, weight = jnp.asarray(windows.target), jnp.asarray(windows.weight)
    predict = _predictor(model, windows, substeps, method, newton=newton, unroll=unroll)

    def residuals(genome):
        err = predict(layout.decode(genome)) - target
        return jnp.where(weight[..., None] > 0, err, 0.0)

    return residuals


def constant_velocity_cost(windows: Windows) -> float:
    """The zero-force predictor's summed squared error (m^2) on ``windows``' terms: each
    start's positions carried on at its start velocity, ``x0 + k dt v0`` k frames ahead."""
    from ..judge.predictions import constant_velocity

    k = np.arange(1, windows.target.shape[1] + 1)[None, :, None, None]
    carried = constant_velocity(windows.x0[:, None], windows.v0[:, None], k * windows.dt)
    err = carried - windows.target
    return float(np.sum(windows.weight[..., None] * err**2))


def unsolved_starts(
    model: Model, windows: Windows, genome, substeps: int = 1, method: str = "euler"
) -> tuple[int, int, float]:
    """(unsolved, starts, largest residual in m): the restart states of ``windows`` (those
    that count) whose start velocity (:func:`~activebonds.physics.integrate.start_velocity`)
    did not converge at ``genome``; (0, S, 0.0) where no solve is needed (one Euler substep)."""
    used = windows.weight[:, 0].any(axis=1)
    n = int(used.sum())
    if substeps == 1:
        return 0, n, 0.0
    params = model.layout.decode(jnp.asarray(genome))
    topo = model.topology

    phases = start_phases(model, windows, substeps)
    psi = None if phases is None else np.asarray(phases(params)[0])[used]

    @jax.jit
    def residuals(x_prev, x0, t0, psi):
        def one(a, b, t, p):
            v, r = start_velocity(
                params, topo, a, b, windows.dt, substeps, method, START_ITERATIONS, t, True, p
            )
            return jnp.where(jnp.all(jnp.isfinite(v)), r, jnp.inf)

        return jax.vmap(one)(x_prev, x0, t0, psi)

    r = np.asarray(residuals(windows.x_prev[used], windows.x0[used], windows.times[used], psi))
    bad = r > 0
    return int(bad.sum()), n, float(r[bad].max()) if bad.any() else 0.0


def starts_line(
    model: Model, windows: Windows, genome, substeps: int = 1, method: str = "euler"
) -> str | None:
    """One line on the start velocities the restart cost could not solve at ``genome``
    (None when every one converged or none needs a solve): how many, why, and what became of
    their predictions."""
    bad, n, worst = unsolved_starts(model, windows, genome, substeps, method)
    if bad == 0:
        return None
    if stiff(model.topology):
        what = (
            "Newton's method stalled at a kink of the contact law within the frame (a contact "
            "starting, ending or sticking); they start from its last iterate"
        )
    else:
        what = "the fixed point diverged (forces too stiff for the frame); they cost +inf"
    return (
        f"start velocities ({substeps} {method} substeps): {bad} of {n} restart states not "
        f"solved to {START_TOLERANCE:g} of the frame's displacement (largest residual "
        f"{worst * 1000:.3g} mm): {what}"
    )


def rms_mm(cost, n_terms: int):
    """A summed squared error (m^2) shown as the RMS position error in millimetres."""
    return np.sqrt(np.asarray(cost, dtype=np.float64) / max(n_terms, 1)) * 1000.0


@dataclass(frozen=True)
class Display:
    """How this cost is shown to people: a summed squared position error (m^2) over
    ``n_terms`` predictions, as the RMS position error in millimetres. The run directory
    records it, so that readers never guess a unit."""

    n_terms: int
    name: str = "rms_mm"
    label: str = "RMS position error"
    unit: str = "mm"

    def __call__(self, cost):
        return rms_mm(cost, self.n_terms)

    def column(self, cost_column: str) -> str:
        """'best_cost' -> 'best_rms_mm'."""
        return f"{cost_column.removesuffix('_cost')}_{self.name}"

    def record(self) -> dict:
        return {"name": self.name, "label": self.label, "unit": self.unit, "terms": self.n_terms}
