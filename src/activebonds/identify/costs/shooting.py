"""Multiple shooting (Bock 1981; e.g. Carbonell et al. 2015): windows of H frames whose start
states are free variables.

The recording (F frames) is cut into windows starting at frames s_k = 0, H, 2H, ...; window k
is integrated H steps from its own state (X_k, V_k) at s_k, which is a variable of the fit
like the model's parameters, not a recorded state. The residuals are

* the position errors of every window at every frame it covers, its start frame included
  (a frame shared by two windows counts once, in the later one), 0 where a marker is missing,
  each times its weight (1 for a recorded sample; a fill's soft prior weighs less);
* the continuity defects between consecutive windows, ``w (x_end,k - X_k+1)`` and
  ``w dt (v_end,k - V_k+1)``, with ``w = CONTINUITY_WEIGHT``, so that at the optimum the
  windows join into one trajectory of the model.

No state is taken from the noisy record, so (unlike the restart cost) the noise does not bias
the forces: this is the output-error estimate, made well-posed for long records by the
windows. H = 1 makes every frame's state a variable; H >= F - 1 is single shooting (a free
run from a free first state). The variables' start values come from the record (gaps filled
by linear interpolation) or from a previous stage's trajectory. An entrained drive's phase at
each window's start is tracked along the record (:func:`window_phases`), not a variable.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ...model.model import Model
from ...physics import phase
from ...physics.integrate import rollout_states

CONTINUITY_WEIGHT = 100.0  # weight of a continuity defect against a position error


@dataclass(frozen=True, eq=False)
class ShootingWindows:
    """Windows of a recording for multiple shooting (NumPy, float64)."""

    starts: np.ndarray  # [K] start frame of each window (in its recording)
    target: np.ndarray  # [K, H + 1, P, D] recorded positions at s_k .. s_k + H (0 if missing)
    weight: np.ndarray  # [K, H + 1, P] 1.0 where the term counts (a position error's factor)
    dt: float
    link: np.ndarray | None = None  # [K - 1] 1.0 where window k + 1 continues window k
    segments: tuple[tuple[int, int, int], ...] = ()  # per recording: (first window, end, frames)
    records: tuple[np.ndarray, ...] = ()  # per recording: positions [F, P, D], NaN if missing
    phases: object = None  # [K] an entrained drive's phase at each start, where given (a fill)

    @property
    def horizon(self) -> int:
        return int(self.target.shape[1] - 1)

    @property
    def n_terms(self) -> int:
        return int(self.weight.sum())

    @property
    def times(self) -> np.ndarray:
        return self.starts * self.dt


def shooting_windows(positions: np.ndarray, mask: np.ndarray, dt: float, horizon: int):
    """Windows of ``horizon`` frames over positions [F, P, D] (NaN where missing), mask [F, P]."""
    n_frames = positions.shape[0]
    if n_frames < 2:
        raise ValueError("multiple shooting needs at least 2 frames")
    h = max(1, min(int(horizon), n_frames - 1))
    starts = np.arange(0, n_frames - 1, h)
    frames = starts[:, None] + np.arange(h + 1)[None, :]  # [K, H + 1]
    inside = frames < n_frames
    frames_c = np.minimum(frames, n_frames - 1)
    x = np.where(mask[..., None], positions, 0.0)
    last = np.zeros(frames.shape, bool)
    last[:-1, -1] = True  # a junction frame counts in the next window (its start)
    weight = mask[frames_c] & (inside & ~last)[..., None]
    k = len(starts)
    return ShootingWindows(
        starts,
        x[frames_c],
        weight.astype(np.float64),
        float(dt),
        link=np.ones(k - 1),
        segments=((0, k, n_frames),),
        records=(np.where(mask[..., None], positions, np.nan),),
    )


def join_shooting(parts: list[ShootingWindows]) -> ShootingWindows:
    """The windows of several recordings as one set; no continuity joins two recordings."""
    if len(parts) == 1:
        return parts[0]
    h = max(w.horizon for w in parts)

    def pad(a):
        extra = h + 1 - a.shape[1]
        return np.concatenate([a, np.zeros((a.shape[0], extra, *a.shape[2:]))], axis=1)

    links, segments, k0 = [], [], 0
    for i, w in enumerate(parts):
        links += [w.link, np.zeros(1)] if i < len(parts) - 1 else [w.link]
        k = len(w.starts)
        segments.append((k0, k0 + k, w.segments[0][2]))
        k0 += k
    return ShootingWindows(
        np.concatenate([w.starts for w in parts]),
        np.concatenate([pad(w.target) for w in parts]),
        np.concatenate([pad(w.weight) for w in parts]),
        parts[0].dt,
        link=np.concatenate(links),
        segments=tuple(segments),
        records=tuple(r for w in parts for r in w.records),
    )


def window_phases(model: Model, windows: ShootingWindows, substeps: int):
    """``params -> [K]`` an entrained drive's phase at each window's start, tracked along its
    recording from the start phase at the recording's first frame
    (:func:`~activebonds.physics.phase.track`): the phase is a window state estimated from
    the record, not a variable of the fit; within a window it moves with the window's state.
    None for a model without an entrained drive. Where the windows carry their phases (a
    fill tracks them along the whole recording), those."""
    topo = model.topology
    if not phase.entrained(topo):
        return None
    if windows.phases is not None:
        return lambda params: windows.phases
    if len(windows.records) != len(windows.segments):
        raise ValueError("an entrained drive needs the windows' recordings to track its phase")
    period = phase.period_frames(model.params, topo, windows.dt)  # (a leading gap's fill)
    signals = [jnp.asarray(phase.recorded_signal(topo, r, period=period)) for r in windows.records]

    def phases(params):
        out = []
        for (k0, k1, _), s in zip(windows.segments, signals, strict=True):
            psi = phase.track(params, topo, s, windows.dt, substeps)
            out.append(psi[windows.starts[k0:k1]])
        return jnp.concatenate(out)

    return phases


def filled(positions: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Positions with every gap filled by linear interpolation in time (ends held)."""
    out = np.array(positions, dtype=np.float64)
    frames = np.arange(positions.shape[0])
    for p in range(positions.shape[1]):
        ok = mask[:, p]
        if not ok.any():
            raise ValueError(f"particle {p} is never recorded")
        for d in range(positions.shape[2]):
            out[:, p, d] = np.interp(frames, frames[ok], positions[ok, p, d])
    return out


def frame_states(positions: np.ndarray, mask: np.ndarray, dt: float):
    """Start values of every frame's state from the record: filled positions and their
    central-difference velocities. [F, P, D] each."""
    x = filled(positions, mask)
    return x, np.gradient(x, dt, axis=0)


def make_shooting(
    model: Model,
    windows: ShootingWindows,
    substeps: int = 1,
    method: str = "euler",
    unroll: bool = False,
):
    """``(genome, states) -> residuals`` (a pytree of arrays, metres) and
    ``(genome, states) -> frame states`` of the windows' trajectories. ``unroll``: the
    substeps written out (:func:`~activebonds.physics.integrate.advance`; the dense path's).

    ``states = (X [K, P, D], V [K, P, D])``: each window's start state. The trajectory's
    ``run`` attribute is its jitted ``(genome, states) -> (positions, velocities)``
    [K, H + 1, P, D] of every window."""
    topo, layout = model.topology, model.layout
    target, weight = jnp.asarray(windows.target), jnp.asarray(windows.weight)
    t0 = jnp.asarray(windows.times)
    dt, h = windows.dt, windows.horizon
    link = jnp.asarray(windows.link)[:, None, None]

    phases = window_phases(model, windows, substeps)

    def run(genome, states):
        params = layout.decode(genome)
        xs0, vs0 = states

        def window(x, v, t, *psi):
            xs, vs = rollout_states(
                params, topo, x, v, dt, h, substeps, method, t, *psi, unroll=unroll
            )[:2]
            return jnp.concatenate([x[None], xs]), jnp.concatenate([v[None], vs])

        extra = () if phases is None else (phases(params),)
        return jax.vmap(window)(xs0, vs0, t0, *extra)  # [K, H + 1, P, D] each

    def residuals(genome, states):
        xs0, vs0 = states
        pos, vel = run(genome, states)
        measured = jnp.where(weight[..., None] > 0, weight[..., None] * (pos - target), 0.0)
        w = CONTINUITY_WEIGHT
        gap_x = link * w * (pos[:-1, -1] - xs0[1:])
        gap_v = link * w * dt * (vel[:-1, -1] - vs0[1:])
        return measured, gap_x, gap_v

    def trajectory(genome, states):
        """Per recording, per-frame (positions, velocities) [F, P, D] along the windows."""
        pos, vel = trajectory.run(genome, states)
        out = []
        for k0, k1, n_frames in windows.segments:
            p, v = pos[k0:k1], vel[k0:k1]
            xs = jnp.concatenate([p[:, :-1].reshape(-1, *p.shape[2:]), p[-1:, -1]])
            vs = jnp.concatenate([v[:, :-1].reshape(-1, *v.shape[2:]), v[-1:, -1]])
            out.append((np.asarray(xs[:n_frames]), np.asarray(vs[:n_frames])))
        return out

    # one compiled program (run eagerly, its ops compiled one by one); a caller may replace
    # it by the same program compiled ahead (:mod:`.compile_ahead`)
    trajectory.run = jax.jit(run)
    return residuals, trajectory


def start_states(windows: ShootingWindows, states):
    """Each window's start state, from per-recording, per-frame states [(x, v) [F, P, D]]."""
    xs, vs = [], []
    for (k0, k1, _), (x, v) in zip(windows.segments, states, strict=True):
        starts = windows.starts[k0:k1]
        xs.append(np.asarray(x)[starts])
        vs.append(np.asarray(v)[starts])
    return np.concatenate(xs), np.concatenate(vs)
