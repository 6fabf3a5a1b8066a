"""What the model says of the record around a gap: how much of its accelerations the model
explains (:func:`one_step_ratio`), the continuity weight that follows (:func:`continuity_weight`),
and an entrained drive's phase tracked along the record (:func:`fill_phases`)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ...model.model import Model
from ...physics import phase
from ..costs.shooting import CONTINUITY_WEIGHT

RATIO_FRAMES = 8  # frames ahead of the prediction that sets the continuity weight
CONTINUITY = 0.3  # least weight of a continuity defect against a position error (metres each)


def continuity_weight(ratio: float) -> float:
    """The weight of a continuity defect (against a position error) for a model whose one-step
    error is ``ratio`` times zero force's: ``CONTINUITY / ratio^2`` within
    [``CONTINUITY``, ``CONTINUITY_WEIGHT``]. A model that explains the accelerations (ratio near
    0: the true model, the noise left) is held to its dynamics as the shooting fit holds it; a
    model that explains little of them (ratio near 1) lets the trajectory leave its dynamics
    where the markers present ask for it, at a cost still large enough to carry the missing
    marker through the gap."""
    if not np.isfinite(ratio) or ratio <= 0.0:
        return CONTINUITY_WEIGHT
    return float(np.clip(CONTINUITY / ratio**2, CONTINUITY, CONTINUITY_WEIGHT))


def one_step_ratio(
    model: Model, genome, positions, mask, dt, first, substeps=1, integrator="euler", phases=None
) -> float:
    """How much of the motion's accelerations the model leaves unexplained: on the frames t of
    ``positions`` [S, M, D] where every marker is present at t - n, t and t + n
    (n = ``RATIO_FRAMES``), the RMS of ``x(t+n) - 2 x(t) + x(t-n) - (n dt)^2 F(x, v, t) / m``
    over the RMS of the second difference alone (zero force's), with v the central difference
    over 2 n frames; NaN without such frames. Over several frames the accelerations outgrow
    the marker noise, which a one-frame ratio would measure instead. (``substeps`` and
    ``integrator`` are the fill's; the ratio reads the forces alone. ``phases`` [S]: an
    entrained drive's phase at each frame.)"""
    from ...physics.forces import total_force

    n = RATIO_FRAMES
    if len(positions) <= 2 * n:
        return float("nan")
    ok = mask[: -2 * n].all(1) & mask[n:-n].all(1) & mask[2 * n :].all(1)
    t = np.flatnonzero(ok) + n
    if not t.size:
        return float("nan")
    x, prev, nxt = positions[t], positions[t - n], positions[t + n]
    params = model.layout.decode(genome)
    v = (nxt - prev) / (2 * n * dt)

    def accel(x0, v0, time, *psi):
        held = phase.at_phase(params, psi[0]) if psi else params
        return total_force(held, model.topology, x0, v0, time) / params.mass[:, None]

    extra = () if phases is None else (jnp.asarray(np.asarray(phases)[t]),)
    a = jax.vmap(accel)(jnp.asarray(x), jnp.asarray(v), jnp.asarray((t + first) * dt), *extra)
    a = np.asarray(a)
    second = nxt - 2.0 * x + prev
    e_model = float(np.sqrt(np.mean(np.square(second - (n * dt) ** 2 * a))))
    e_zero = float(np.sqrt(np.mean(np.square(second))))
    return e_model / e_zero if e_zero > 0.0 else float("nan")


def fill_phases(
    model: Model, genome, positions, mask, dt, substeps=1, psi0=None
) -> np.ndarray | None:
    """An entrained drive's phase at every frame [S] of ``positions`` [S, M, D], tracked
    from ``psi0`` (default: the start phase) at the first frame
    (:func:`~activebonds.physics.phase.track`), the coupling off (the signal at its offset)
    wherever the signal's markers are missing: the phase runs at the drive's frequency there.
    None for a model without one."""
    topo = model.topology
    if not phase.entrained(topo):
        return None
    marks = list(topo.drive.read)
    missing = ~np.asarray(mask, bool)[:, marks].all(axis=1)
    s = phase.signal(topo, positions, np)
    s = np.where(missing.reshape(-1, *[1] * (s.ndim - 1)), 0.0, s)
    params = model.layout.decode(genome)
    return np.asarray(phase.track(params, topo, jnp.asarray(s), dt, substeps, psi0))
