"""Forces of every element of DESIGN.md §2, for one individual.

One contract per bond family: ``family(params, topology, x, v) -> F`` with ``x, v`` of shape
[P, D] and ``F`` of shape [P, D]. Vectorise over a population with ``jax.vmap`` and over time
with ``jax.lax.scan`` (see :mod:`activebonds.physics.integrate`).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..model.params import Params, Topology


def uniform_field(params: Params, topo: Topology, x, v):
    """F_p = m_p g (gravity)."""
    return jnp.broadcast_to(params.mass[:, None] * params.gravity[None, :], x.shape)


def _select(index, n: int) -> np.ndarray:
    """One-hot selection matrix [len(index), n]: ``_select(i, P) @ x == x[i]``.

    Gathers and scatters become products with constant matrices, which vmap into one large
    matrix product over the population instead of many small scatters (much faster on CPU)."""
    out = np.zeros((len(index), n))
    out[np.arange(len(index)), index] = 1.0
    return out


def unary(params: Params, topo: Topology, x, v):
    """Unary spring + damper to the environment: F_p += -k_u (x_p - a) - c_u v_p."""
    if topo.unary.size == 0:
        return jnp.zeros_like(x)
    sel = _select(topo.unary, topo.n_particles).astype(x.dtype)
    f = -params.unary_k[:, None] * (sel @ x - params.unary_anchor) - params.unary_c[:, None] * (
        sel @ v
    )
    return sel.T @ f


def bond_kinematics(topo: Topology, x, v):
    """Per binary bond: unit vector u (i -> j), length L, elongation rate Ldot."""
    diff = _bond_difference(topo).astype(x.dtype)
    d = diff @ x
    length = jnp.sqrt(jnp.sum(d * d, axis=-1))
    u = d / length[:, None]
    rate = jnp.sum((diff @ v) * u, axis=-1)
    return u, length, rate


def _bond_difference(topo: Topology) -> np.ndarray:
    """[B, P] matrix with +1 at j and -1 at i, so ``diff @ x`` is x_j - x_i for each bond."""
    n = topo.n_particles
    return _select(topo.binary[:, 1], n) - _select(topo.binary[:, 0], n)


def activation(params: Params, topo: Topology, elongation, rate):
    """Neuron b: a_b = tanh(sum_{j != b} (wL_bj e_j + wV_bj Ldot_j) - theta_b)."""
    off = 1.0 - np.eye(topo.n_binary)
    drive = jnp.sum(params.w_len * off * elongation[None, :], axis=-1) + jnp.sum(
        params.w_rate * off * rate[None, :], axis=-1
    )
    return jnp.tanh(drive - params.threshold)


def binary(params: Params, topo: Topology, x, v):
    """Viscoelastic (and mechanical-neural) binary bonds: tension f = k (L - l0) + c Ldot
    (+ g a for a neural bond); F_i += f u, F_j -= f u, so positive tension pulls together."""
    if topo.n_binary == 0:
        return jnp.zeros_like(x)
    u, length, rate = bond_kinematics(topo, x, v)
    elongation = length - params.l0
    tension = params.k * elongation + params.c * rate
    if topo.neural.any():
        a = activation(params, topo, elongation, rate)
        tension = tension + jnp.where(topo.neural, params.gain * a, 0.0)
    diff = _bond_difference(topo).astype(x.dtype)
    return -(diff.T @ (tension[:, None] * u))


def ternary(params: Params, topo: Topology, x, v):
    """Flexion springs: E = 1/2 k_f (cos th - cos th0)^2 with th the angle at the middle
    particle; F = -grad E on all three particles (they sum to zero)."""
    if topo.ternary.size == 0:
        return jnp.zeros_like(x)
    n = topo.n_particles
    si, sj, sk = (_select(topo.ternary[:, c], n).astype(x.dtype) for c in range(3))
    a = (si - sj) @ x
    b = (sk - sj) @ x
    na = jnp.sqrt(jnp.sum(a * a, axis=-1))[:, None]
    nb = jnp.sqrt(jnp.sum(b * b, axis=-1))[:, None]
    cos = jnp.sum(a * b, axis=-1)[:, None] / (na * nb)
    dcos_da = b / (na * nb) - cos * a / (na * na)
    dcos_db = a / (na * nb) - cos * b / (nb * nb)
    s = -params.tern_k[:, None] * (cos - jnp.cos(params.tern_angle)[:, None])
    fi, fk = s * dcos_da, s * dcos_db
    return si.T @ fi + sk.T @ fk - sj.T @ (fi + fk)


FAMILIES = (uniform_field, unary, binary, ternary)


def total_force(params: Params, topo: Topology, x, v):
    """Sum of every family's forces, [P, D]."""
    f = FAMILIES[0](params, topo, x, v)
    for family in FAMILIES[1:]:
        f = f + family(params, topo, x, v)
    return f


def neuron_activity(params: Params, topo: Topology, x, v):
    """Activations of all neurons at a state (0 for non-neural bonds); for saturation reports."""
    _, length, rate = bond_kinematics(topo, x, v)
    a = activation(params, topo, length - params.l0, rate)
    return jnp.where(topo.neural, a, 0.0)
