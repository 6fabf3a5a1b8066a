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


def _accumulate(n: int, terms) -> jnp.ndarray:
    """Sum per-element force rows into particles: ``terms`` is a list of (index array,
    sign, rows [K, D]); returns [n, D]. The topology is static, so this unrolls into plain
    slices and adds (a scatter-add vmapped over a population is slow on CPU)."""
    dim = terms[0][2].shape[-1]
    dtype = terms[0][2].dtype
    per_particle = [[] for _ in range(n)]
    for index, sign, rows in terms:
        for k, p in enumerate(np.asarray(index)):
            per_particle[int(p)].append((sign, rows[k]))
    out = []
    for contributions in per_particle:
        total = jnp.zeros((dim,), dtype)
        for sign, row in contributions:
            total = total + row if sign > 0 else total - row
        out.append(total)
    return jnp.stack(out)


def unary(params: Params, topo: Topology, x, v):
    """Unary spring + damper to the environment: F_p += -k_u (x_p - a) - c_u v_p."""
    if topo.unary.size == 0:
        return jnp.zeros_like(x)
    idx = topo.unary
    f = -params.unary_k[:, None] * (x[idx] - params.unary_anchor) - params.unary_c[:, None] * v[idx]
    return _accumulate(topo.n_particles, [(idx, 1, f)])


def bond_kinematics(topo: Topology, x, v):
    """Per binary bond: unit vector u (i -> j), length L, elongation rate Ldot."""
    i, j = topo.binary[:, 0], topo.binary[:, 1]
    d = x[j] - x[i]
    length = jnp.sqrt(jnp.sum(d * d, axis=-1))
    u = d / length[:, None]
    rate = jnp.sum((v[j] - v[i]) * u, axis=-1)
    return u, length, rate


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
    f = tension[:, None] * u
    return _accumulate(topo.n_particles, [(topo.binary[:, 0], 1, f), (topo.binary[:, 1], -1, f)])


def ternary(params: Params, topo: Topology, x, v):
    """Flexion springs: E = 1/2 k_f (cos th - cos th0)^2 with th the angle at the middle
    particle; F = -grad E on all three particles (they sum to zero)."""
    if topo.ternary.size == 0:
        return jnp.zeros_like(x)
    i, j, k = topo.ternary[:, 0], topo.ternary[:, 1], topo.ternary[:, 2]
    a = x[i] - x[j]
    b = x[k] - x[j]
    na = jnp.sqrt(jnp.sum(a * a, axis=-1))[:, None]
    nb = jnp.sqrt(jnp.sum(b * b, axis=-1))[:, None]
    cos = jnp.sum(a * b, axis=-1)[:, None] / (na * nb)
    dcos_da = b / (na * nb) - cos * a / (na * na)
    dcos_db = a / (na * nb) - cos * b / (nb * nb)
    s = -params.tern_k[:, None] * (cos - jnp.cos(params.tern_angle)[:, None])
    fi, fk = s * dcos_da, s * dcos_db
    terms = [(i, 1, fi), (k, 1, fk), (j, -1, fi + fk)]
    return _accumulate(topo.n_particles, terms)


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
