"""A periodic force on one particle, a Fourier series in the drive's phase (DESIGN.md §2).

F_p += sum_h (C_h cos(h psi) + S_h sin(h psi)), h = 1 .. 8, with C_h and S_h vectors (N, one
value per axis; file keys ``cos1`` .. ``cos8`` and ``sin1`` .. ``sin8``, genes ``cos1[axis]``;
a harmonic the bond does not give is 0 and no gene). psi is the model's rhythmic drive
(``[drive]``): the clock 2 pi f t, or with ``[drive] coupling`` the entrained phase, a state
of the model pulled by the body (:mod:`activebonds.physics.phase`), written into this kind's
parameters as ``drive_state`` like the neural bonds'. The drive's frequency, coupling gain
and start phase are shared with the neural bonds (the same genes, ``drive.frequency`` ...),
so a model whose drive only moves particles needs no neuron.

A periodic bond is a central pattern generator acting on the body directly: with springs
and anchors that hold each particle near its place and damping, a forced body converges to a
periodic orbit of the drive's period, and an entrained drive keeps that orbit in step with
the body's own rhythm. Given psi (tracked along a record), the force is linear in every
coefficient: the exact least squares solves for all of them.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .accumulate import accumulate
from .binary import DRIVE_STATE, drive_parameters
from .kind import BondKind, LinearPart, MujocoForm, Parameter

HARMONICS = 8  # the highest harmonic a bond may give
TERMS = tuple((f"{w}{h}", w, h) for h in range(1, HARMONICS + 1) for w in ("cos", "sin"))


def phase_of(params, t):
    """The drive's phase psi for each bond [N]: the entrained state where the integrator
    wrote it, else the clock 2 pi f t."""
    if DRIVE_STATE in params:
        return params[DRIVE_STATE]
    return 2.0 * jnp.pi * params["drive_frequency"] * t


def forces(params, topology, x, v, t):
    idx = topology["particles"][:, 0]
    psi = phase_of(params, t)[:, None]  # [N, 1]
    f = jnp.zeros((idx.shape[0], x.shape[1]), x.dtype)
    for key, wave, h in TERMS:
        basis = jnp.cos(h * psi) if wave == "cos" else jnp.sin(h * psi)
        f = f + basis * params[key]
    return accumulate(x.shape[0], [(idx, 1, f)])


def _switch_off(values, index, topology, genes):
    for key, _, _ in TERMS:
        values[key][:] = 0.0
    return values


def _columns(values, index, topology, x, v, unknowns):
    """F_p += cos(h psi) C_h + sin(h psi) S_h: unknowns every free coefficient, psi at each
    start (``unknowns.phase``: the entrained drive's tracked phase, else the clock)."""
    d = x.shape[-1]
    psi = unknowns.phase
    if psi is None:
        f = float(np.asarray(values["drive_frequency"])[0]) if len(values["drive_frequency"]) else 0
        psi = 2.0 * np.pi * f * np.asarray(unknowns.time, np.float64)
    psi = np.asarray(psi, np.float64)
    for n, p in enumerate(np.asarray(topology["particles"][:, 0])):
        for key, wave, h in TERMS:
            basis = np.cos(h * psi) if wave == "cos" else np.sin(h * psi)
            for a in range(d):
                g = int(index[key][n, a])
                if g >= 0:
                    unknowns.gene(g)[:, p, a] += basis
                else:
                    unknowns.known[:, p, a] += basis * float(values[key][n, a])


KIND = BondKind(
    off=tuple(key for key, _, _ in TERMS),
    name="periodic",
    arity=1,
    parameters=tuple(
        Parameter(
            key, key, 0.0, lambda v: (v - 1e3, v + 1e3), log=False, form="vector", needs="drive"
        )
        for key, _, _ in TERMS
    ),
    shared=drive_parameters(None),
    forces=forces,
    timed=True,
    internal=False,
    what="periodic forces",
    noun="periodic force",
    linear=LinearPart(frozenset(key for key, _, _ in TERMS), _switch_off, _columns),
    mujoco=MujocoForm(None, why="a force that follows the drive's phase has no MJCF element"),
)
