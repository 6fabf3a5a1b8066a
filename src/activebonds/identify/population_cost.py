"""The one-step cost of a whole population at once (the ES's fast path).

With the paper's one-step cost (horizon 1, semi-implicit Euler, one substep) every prediction
starts from a *recorded* state, so the bond lengths L, elongation rates Ldot and unit vectors u
at the restart states do not depend on the genome. The prediction of individual n is

    x_1 = x_0 + dt v_0 + dt^2 a_n(x_0, v_0, t_0),

so the error is a fixed part (``x_0 + dt v_0 - target``, computed once in float64) plus
``dt^2 a_n``. For binary bonds (standard and mechanical-neural) the neuron inputs of the whole
population are one matrix product, ``[S, 2B] @ [2B, N B]`` (restarts x [L, Ldot] against every
individual's off-diagonal weights), plus a per-individual bias (``-W_L l0 - theta`` and the
rhythmic drive); the tensions become particle forces by a product with the fixed
``u``-weighted signed incidence of each restart. Other bond kinds, and the uniform field, are
evaluated per individual (vmapped) at the same fixed states.

The result equals :func:`~activebonds.identify.cost.make_cost` vmapped over the population (to
rounding: tested), and is used by the ES whenever the one-step form applies
(:func:`make_population_cost` returns None otherwise, and the loop vmaps the per-individual
cost). ``dtype=float32`` evaluates in single precision (the fixed part is formed in float64
first, so that no cancellation of metre-sized positions happens in float32); costs come back
in the caller's precision.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .. import bonds
from ..bonds.accumulate import gather_table
from ..model.model import Model
from .cost import Windows

_BINARY = "binary"
DENSE_LIMIT = 512  # bonds x particles up to which tensions are spread by a dense product


def applies(windows: Windows, substeps: int, method: str) -> bool:
    """Whether the one-step population form computes this cost."""
    return windows.horizon == 1 and substeps == 1 and method == "euler"


def make_population_cost(
    model: Model, windows: Windows, substeps: int = 1, method: str = "euler", dtype=None
):
    """``genes [N, G] -> (cost [N], local [N, P])`` for the one-step cost, or None where the
    one-step form does not apply (a longer horizon, Verlet or substeps)."""
    if not applies(windows, substeps, method):
        return None
    layout, topo = model.layout, model.topology
    # Restarts that count (a start with missing inputs counts nowhere: its state may be 0).
    used = windows.weight[:, 0].any(axis=1)
    x0 = np.asarray(windows.x0[used], np.float64)
    v0 = np.asarray(windows.v0[used], np.float64)
    t0 = windows.times[used]
    weight = windows.weight[used, 0]  # [S, P]
    fixed = x0 + windows.dt * v0 - windows.target[used, 0]  # [S, P, D], float64
    work = dtype or jnp.result_type(float)
    dt2 = windows.dt**2
    kinds = topo.active()
    binary = _BINARY in kinds
    others = tuple(k for k in kinds if k != _BINARY)
    if binary:
        geometry = _binary_geometry(topo.bonds[_BINARY], x0, v0, topo.n_particles)
        geometry = {k: v if k == "bond" else jnp.asarray(v, work) for k, v in geometry.items()}
        neural = np.asarray(topo.bonds[_BINARY]["neural"], bool)
    fixed_j, weight_j = jnp.asarray(fixed, work), jnp.asarray(weight, work)
    x0_j, v0_j, t0_j = (jnp.asarray(a, work) for a in (x0, v0, t0))
    n_p, dim = topo.n_particles, topo.dimension

    def other_forces(params):  # one individual: [S, P, D]
        def at(x, v, t):
            f = jnp.zeros_like(x)
            for kind in others:
                f = f + bonds.get(kind).forces(params.bonds[kind], topo.bonds[kind], x, v, t)
            return f

        return jax.vmap(at)(x0_j, v0_j, t0_j)

    def evaluate(genes):
        params = jax.vmap(layout.decode)(genes)
        params = jax.tree.map(lambda a: a.astype(work), params)
        n, n_s = genes.shape[0], fixed.shape[0]
        # the population is the last axis throughout (contiguous: vectorised along it)
        force = jnp.zeros((n_s, n_p, dim, n), work)  # [S, P, D, N]
        if binary:
            bond_params = params.bonds[_BINARY]
            force = force + _binary_forces(bond_params, geometry, neural, t0_j, n_p, dim)
        if others:
            force = force + jax.vmap(other_forces)(params).transpose(1, 2, 3, 0)
        inv_m = (1.0 / params.mass).T  # [P, N]
        acc = params.gravity.T[None, None] + force * inv_m[None, :, None]  # F = m g + bonds
        err2 = jnp.sum((fixed_j[..., None] + dt2 * acc) ** 2, axis=2)  # [S, P, N]
        local = jnp.sum(jnp.where(weight_j[..., None] > 0, err2, 0.0), axis=0).T  # [N, P]
        local = jnp.where(jnp.isfinite(local), local, jnp.inf)
        return jnp.sum(local, axis=-1), local

    return evaluate


def _binary_geometry(topology, x0, v0, n_particles: int) -> dict[str, np.ndarray]:
    """Per restart: lengths L [S, B, 1], rates Ldot [S, B, 1], the neuron inputs [S, 2B], and
    the map from tensions to particle forces: dense [S, P D, B] (``+u`` at a bond's first
    particle, ``-u`` at its second) or, for large models, gathered by particle."""
    pairs = np.asarray(topology["particles"])
    i, j = pairs[:, 0], pairs[:, 1]
    d = x0[:, j] - x0[:, i]
    length = np.linalg.norm(d, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = d / length[..., None]
    rate = np.sum((v0[:, j] - v0[:, i]) * u, axis=-1)
    s, b, dim = u.shape
    out = {
        "length": length[..., None],
        "rate": rate[..., None],
        "inputs": np.concatenate([length, rate], axis=1),
    }
    if spread_form(b, n_particles) == "dense":
        spread = np.zeros((s, n_particles, dim, b))
        spread[:, i, :, np.arange(b)] += u.transpose(1, 0, 2)
        spread[:, j, :, np.arange(b)] -= u.transpose(1, 0, 2)
        out["spread"] = spread.reshape(s, n_particles * dim, b)
    else:  # particle p sums the tensions of bonds table[p] along ends[:, p] (0 past its ends)
        table, total = gather_table(n_particles, [i, j])
        bond = np.where(table < total, table % b, 0)
        sign = np.where(table < total, np.where(table < b, 1.0, -1.0), 0.0)
        out["ends"] = sign[None, :, :, None] * u[:, bond]  # [S, P, K, D]
        out["bond"] = bond
    return out


def spread_form(n_bonds: int, n_particles: int) -> str:
    """How tensions become particle forces: "dense" (a product with the signed incidence of
    every restart, [P D, B]: fastest while small) or "gathered" (each particle's bonds by
    index: work grows with the bond ends, not with bonds x particles)."""
    return "dense" if n_bonds * n_particles <= DENSE_LIMIT else "gathered"


def _binary_forces(params, geometry, neural: np.ndarray, t0, n_p: int, dim: int):
    """Forces of the binary bonds of every individual at every restart: [S, P, D, N]."""
    length, rate = geometry["length"], geometry["rate"]  # [S, B, 1]
    rest = params["rest_length"].T  # [B, N]
    elongation = length - rest[None]  # [S, B, N]
    tension = params["stiffness"].T[None] * elongation + params["damping"].T[None] * rate
    if neural.any():
        b = len(neural)
        off = jnp.asarray(1.0 - np.eye(b), length.dtype)
        w_len = params["length_weights"] * off  # [N, B, B]
        w_rate = params["rate_weights"] * off
        # neuron inputs: [S, 2B] @ [2B, B N] -> [S, B, N]
        n = w_len.shape[0]
        weights = jnp.concatenate([w_len, w_rate], axis=2).transpose(2, 1, 0)  # [2B, B, N]
        net = (geometry["inputs"] @ weights.reshape(2 * b, b * n)).reshape(-1, b, n)
        bias = -jnp.einsum("nbj,nj->bn", w_len, params["rest_length"]) - params["threshold"].T
        net = net + bias[None]
        if "drive_weight" in params:
            freq = jnp.broadcast_to(params["drive_frequency"], params["rest_length"].shape).T
            phase = 2.0 * jnp.pi * freq[None] * t0[:, None, None] + params["drive_phase"].T[None]
            net = net + params["drive_weight"].T[None] * jnp.sin(phase)
        gain = jnp.where(jnp.asarray(neural)[:, None], params["gain"].T, 0.0)  # [B, N]
        tension = tension + gain[None] * jnp.tanh(net)
    n_s, n = tension.shape[0], tension.shape[-1]
    if "spread" in geometry:  # [S, P D, B] @ [S, B, N]
        return jnp.matmul(geometry["spread"], tension).reshape(n_s, n_p, dim, n)
    bond, ends = geometry["bond"], geometry["ends"]  # [P, K], [S, P, K, D]
    return jnp.einsum("spkd,spkn->spdn", ends, tension[:, bond])
