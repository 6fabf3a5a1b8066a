"""Forces of every element of DESIGN.md §2, for one individual.

The uniform field (gravity x mass) is global; every bond kind's forces come from its
declaration in :mod:`activebonds.bonds` (``kind.forces(params.bonds[name],
topology.bonds[name], x, v, t)``), summed in registry order. ``x, v`` have shape [P, D], and so
has every force; ``t`` is the time in seconds from the first frame of the data window (or of
the simulation), a scalar, for kinds whose forces depend on it (a unary bond's moving anchor). Vectorise over a population with ``jax.vmap`` and over time with
``jax.lax.scan`` (see :mod:`activebonds.physics.integrate`).
"""

from __future__ import annotations

import jax.numpy as jnp

from .. import bonds
from ..bonds.accumulate import accumulate as _accumulate  # noqa: F401 (its old home)
from ..model.params import Params, Topology

__all__ = ["bond_forces", "neuron_activity", "total_force", "uniform_field"]


def uniform_field(params: Params, topo: Topology, x, v, t=0.0):
    """F_p = m_p g (gravity)."""
    return jnp.broadcast_to(params.mass[:, None] * params.gravity[None, :], x.shape)


def bond_forces(kind: str, params: Params, topo: Topology, x, v, t=0.0):
    """The forces of the bonds of one kind ([P, D]; zero without bonds or when disabled)."""
    if kind in topo.disabled or topo.count(kind) == 0:
        return jnp.zeros_like(x)
    return bonds.get(kind).forces(params.bonds[kind], topo.bonds[kind], x, v, t)


def total_force(params: Params, topo: Topology, x, v, t=0.0):
    """Uniform field plus every enabled kind's bond forces at time ``t``, [P, D]."""
    f = uniform_field(params, topo, x, v)
    for kind in topo.active():
        f = f + bonds.get(kind).forces(params.bonds[kind], topo.bonds[kind], x, v, t)
    return f


def neuron_activity(params: Params, topo: Topology, x, v, t=0.0):
    """Activations of the neurons of every kind that has them at a state and time ``t``, bonds
    in registry order (0 for bonds without a neuron, and for a disabled kind); for saturation
    reports."""
    parts = []
    for name in topo.bonds:
        kind = bonds.get(name)
        if kind.activity is None:
            continue
        if name in topo.disabled or topo.count(name) == 0:
            parts.append(jnp.zeros((topo.count(name),), x.dtype))
        else:
            args = (x, v, t) if kind.timed else (x, v)
            parts.append(kind.activity(params.bonds[name], topo.bonds[name], *args))
    if not parts:
        return jnp.zeros((0,), x.dtype)
    return parts[0] if len(parts) == 1 else jnp.concatenate(parts)
