"""The entrained drive's phase (DESIGN.md §2, "Entrained drive").

Without entrainment the neurons read the clock ``2 pi f t``. With ``[drive] coupling`` the
drive's phase psi is a state of the model, advanced by its frequency and pulled by the body
(Owaki et al. 2013's phase oscillator with feedback, the load replaced by a marker signal):

    d psi / dt = 2 pi f - sigma s(x) cos psi,

``s`` the coupling's signal (a particle's height or the distance between two particles, minus a
fixed offset), ``sigma`` its gain
(gene ``drive.coupling.gain``). A periodic signal ``s = s0 + A cos(Omega t + alpha)`` locks
the phase to it (averaged over a cycle, the phase difference obeys ``d delta / dt = 2 pi f -
Omega - (sigma A / 2) cos(delta + ...)``) when ``sigma A / 2 > |2 pi f - Omega|``: the drive
follows the body's gait instead of drifting against it.

With one signal, lock and unevenness are one number: ``s cos psi = A/2 [cos(theta - psi) +
cos(theta + psi)]`` for ``s = A cos theta``, the first term locking psi to the gait, the second
making it run unevenly twice a period by as much. A second signal ``s_b`` (``[drive.coupling]
quadrature``, gain ``sigma_b``, gene ``drive.coupling.quadrature.gain``, either sign) read
against ``sin psi``,

    d psi / dt = 2 pi f - sigma s cos psi - sigma_b s_b sin psi,

cancels the second term when it is a quarter period from the first and ``sigma_b A_b =
sigma A`` (``s_b = A sin theta``: the pull is ``sigma A cos(theta - psi)``, constant along the
period once locked; Kuramoto's coupling to the gait's own phase). Without it the rate is
computed as before, bit for bit.

The integrators carry psi beside (x, v) and advance it at every substep by explicit Euler from
the substep's start state (:mod:`activebonds.physics.integrate`), writing it into the binary
bonds' parameters for the forces (:func:`at_phase`). Where a prediction starts from a
recorded state, psi there is estimated from the record by :func:`track`: the same equation
integrated along the recorded signal (linear between frames, at the same substeps) from the
start phase (gene ``drive.coupling.start_phase``) at the window's first frame. A window that
starts after the model's time origin (a held-out window, ``offset`` frames later) is tracked
from the origin too: the unrecorded frames in between get the window's first signal period
repeated backwards (:func:`extended_back`), so a clock-like drive (small gain) runs on as a
clock would, and a locked one arrives locked to the gait at the window's first frame.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .. import bonds
from ..bonds.binary import DRIVE_STATE
from ..model.params import Params, Topology


def entrained(topo: Topology) -> bool:
    """Whether the model's drive is entrained (its phase a state)."""
    return getattr(topo, "drive", None) is not None


def numbers(params: Params, topo: Topology):
    """(f in Hz, gain sigma, start phase) of the drive, from the bond that holds them."""
    held, k = params.bonds[topo.drive.kind], topo.drive.holder
    return held["drive_frequency"][k], held["drive_gain"][k], held["drive_start"][k]


def start_phase(params: Params, topo: Topology):
    """psi at the first frame of a window (or of a simulation)."""
    return numbers(params, topo)[2]


def quadrature_gain(params: Params, topo: Topology):
    """The gain sigma_b of the coupling's second signal (read against sin psi)."""
    return params.bonds[topo.drive.kind]["drive_quadrature_gain"][topo.drive.holder]


def _one(c, x, xp):
    """One signal (``c``: its particles, axis, offset) at positions x [..., P, D]."""
    if len(c.particles) == 1:
        return x[..., c.particles[0], c.axis] - c.offset
    d = x[..., c.particles[1], :] - x[..., c.particles[0], :]
    return xp.sqrt(xp.sum(d * d, axis=-1)) - c.offset


def signal(topo: Topology, x, xp=jnp):
    """The coupling's signal at positions x [..., P, D], minus its offset: a particle's
    height, or the distance between two particles (``xp``: the array module); with a
    second signal (``quadrature``) the pair [..., 2], the first signal then the second."""
    c = topo.drive
    if c.quadrature is None:
        return _one(c, x, xp)
    return xp.stack([_one(c, x, xp), _one(c.quadrature, x, xp)], axis=-1)


def rate_of(params: Params, topo: Topology, s, psi):
    """d psi / dt for signal ``s`` (with a second signal, ``s`` [..., 2]: the pair)."""
    f, gain, _ = numbers(params, topo)
    if topo.drive.quadrature is None:
        return 2.0 * jnp.pi * f - gain * s * jnp.cos(psi)
    gain_b = quadrature_gain(params, topo)
    return 2.0 * jnp.pi * f - gain * s[..., 0] * jnp.cos(psi) - gain_b * s[..., 1] * jnp.sin(psi)


def rate(params: Params, topo: Topology, x, psi):
    """d psi / dt at positions x [P, D] and phase psi."""
    return rate_of(params, topo, signal(topo, x), psi)


def at_phase(params: Params, psi) -> Params:
    """The parameters with the drive's phase set for the forces of every kind that reads the
    drive (every binary bond reads it, only those with a drive weight are moved by it; every
    periodic force)."""
    out = dict(params.bonds)
    for kind in bonds.drive_kinds():
        if kind not in out:
            continue
        held = dict(out[kind])
        held[DRIVE_STATE] = jnp.broadcast_to(psi, jnp.shape(held["drive_frequency"]))
        out[kind] = held
    return params._replace(bonds=out)


def recorded_signal(
    topo: Topology, positions: np.ndarray, mask: np.ndarray | None = None, period: int = 0
):
    """The signal along a recording [F] (NumPy; [F, 2] with a second signal): positions
    [F, P, D] (NaN or ``mask`` False where missing), gaps filled linearly in time, the end
    held; the frames before the signal is first recorded get its first period repeated
    backwards (:func:`extended_back`: the period of :func:`signal_period` of the first
    signal, else ``period`` frames, else held)."""
    c = topo.drive
    s = signal(topo, np.asarray(positions, np.float64), np)
    ok = np.isfinite(s) if s.ndim == 1 else np.isfinite(s).all(axis=1)
    if mask is not None:
        ok &= np.asarray(mask, bool)[:, list(c.read)].all(axis=1)
    if not ok.any():
        raise ValueError("the entrained drive's signal particle is never recorded")
    frames = np.arange(len(s))
    first = int(np.argmax(ok))
    if s.ndim == 1:
        s = np.interp(frames[first:], frames[ok], s[ok])
    else:
        s = np.stack([np.interp(frames[first:], frames[ok], col[ok]) for col in s.T], axis=1)
    if first == 0:
        return s
    first_signal = s if s.ndim == 1 else s[:, 0]
    return extended_back(s, first, signal_period(first_signal, period or len(s)))


def period_frames(params: Params, topo: Topology, dt: float) -> int:
    """The drive's period in frames (from its frequency), at least 1: the signal's period
    where the recording is too short to measure it."""
    f = float(np.asarray(numbers(params, topo)[0]))
    return max(1, round(1.0 / (f * dt))) if f > 0 else 1


def signal_period(s: np.ndarray, fallback: int) -> int:
    """The period (frames) of a recorded signal [F]: the highest lag of the first positive
    lobe of its autocorrelation (mean removed, unbiased) after its first zero crossing,
    within the first three quarters of the lags; ``fallback`` where there is none (a signal
    too short or not periodic)."""
    s = np.asarray(s, np.float64) - np.mean(s)
    n = len(s)
    if n < 8 or not np.any(s):
        return fallback
    ac = np.correlate(s, s, "full")[n - 1 :] / (n - np.arange(n))
    ac = ac[: (3 * n) // 4]
    below = np.flatnonzero(ac <= 0)
    if below.size == 0:
        return fallback
    above = below[0] + np.flatnonzero(ac[below[0] :] > 0)  # the lobe after the first zero
    if above.size == 0:
        return fallback
    end = above[0] + np.flatnonzero(ac[above[0] :] <= 0)
    stop = int(end[0]) if end.size else len(ac)
    return int(above[0] + np.argmax(ac[above[0] : stop]))


def extended_back(s: np.ndarray, before: int, period: int) -> np.ndarray:
    """The signal [before + F, ...] with ``before`` frames prepended: its first ``period``
    frames repeated backwards in time (a periodic extension joining at its first frame)."""
    s = np.asarray(s, np.float64)
    period = max(1, min(int(period), len(s)))
    k = np.arange(-before, 0)
    return np.concatenate([s[k % period], s])


def track(params: Params, topo: Topology, s, dt, substeps: int = 1, psi0=None):
    """The phase at every frame [F] of a recording whose signal is ``s`` [F] ([F, 2] with a
    second signal), from ``psi0`` (default: the start phase) at its first frame: explicit
    Euler at ``substeps`` per frame, the signal linear between frames (as the integrator
    advances it along the model's own positions)."""
    s = jnp.asarray(s)
    psi0 = start_phase(params, topo) if psi0 is None else psi0
    h = dt / substeps
    frac = jnp.arange(substeps) / substeps

    def frame(psi, ends):
        a, b = ends
        for k in range(substeps):
            psi = psi + h * rate_of(params, topo, a + frac[k] * (b - a), psi)
        return psi, psi

    psi0 = jnp.asarray(psi0, s.dtype)
    _, rest = jax.lax.scan(frame, psi0, (s[:-1], s[1:]))
    return jnp.concatenate([psi0[None], rest])
