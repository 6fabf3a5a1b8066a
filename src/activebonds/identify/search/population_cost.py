"""The one-step cost of a whole population at once (the ES's fast path).

With the paper's one-step cost (horizon 1, semi-implicit Euler, one substep) every prediction
starts from a *recorded* state, so the bond geometry at the restart states (lengths, rates,
directions) does not depend on the genome. The prediction of individual n is

    x_1 = x_0 + dt v_0 + dt^2 a_n(x_0, v_0, t_0),

so the error is a fixed part (``x_0 + dt v_0 - target``, computed once in float64) plus
``dt^2 a_n``. A bond kind that declares a population form
(:class:`~activebonds.bonds.kind.PopulationForm`) computes its forces for every individual at
once from that fixed geometry (e.g. the neuron inputs of the whole population as one matrix
product); the other kinds, and the uniform field, are evaluated per individual (vmapped) at
the same fixed states.

The result equals :func:`~activebonds.identify.costs.windows.make_cost` vmapped over the population (to
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

from ... import bonds
from ...model.model import Model
from ...physics import phase
from ...physics.integrators import Integrator
from ..costs.windows import Windows

DENSE_LIMIT = 512  # bonds x particles up to which a kind's rows are spread by a dense product


def applies(windows: Windows, substeps: int, method: str) -> bool:
    """Whether the one-step population form computes this cost."""
    return windows.horizon == 1 and Integrator(method, substeps).exact_backward


def make_population_cost(
    model: Model, windows: Windows, substeps: int = 1, method: str = "euler", dtype=None
):
    """``genes [N, G] -> (cost [N], local [N, P])`` for the one-step cost, or None where the
    one-step form does not apply (a longer horizon, Verlet or substeps)."""
    if not applies(windows, substeps, method) or phase.entrained(model.topology):
        return None  # (an entrained drive's phase depends on the genome along the record)
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
    n_p, dim = topo.n_particles, topo.dimension
    kinds = topo.active()
    batched = tuple(k for k in kinds if bonds.get(k).population is not None)
    others = tuple(k for k in kinds if bonds.get(k).population is None)
    prepared = {
        k: bonds.get(k).population.prepare(topo.bonds[k], x0, v0, n_p, work, DENSE_LIMIT)
        for k in batched
    }
    fixed_j, weight_j = jnp.asarray(fixed, work), jnp.asarray(weight, work)
    x0_j, v0_j, t0_j = (jnp.asarray(a, work) for a in (x0, v0, t0))

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
        for kind in batched:
            form = bonds.get(kind).population
            force = force + form.forces(params.bonds[kind], prepared[kind], t0_j, n_p, dim)
        if others:
            force = force + jax.vmap(other_forces)(params).transpose(1, 2, 3, 0)
        inv_m = (1.0 / params.mass).T  # [P, N]
        acc = params.gravity.T[None, None] + force * inv_m[None, :, None]  # F = m g + bonds
        err2 = jnp.sum((fixed_j[..., None] + dt2 * acc) ** 2, axis=2)  # [S, P, N]
        local = jnp.sum(jnp.where(weight_j[..., None] > 0, err2, 0.0), axis=0).T  # [N, P]
        local = jnp.where(jnp.isfinite(local), local, jnp.inf)
        return jnp.sum(local, axis=-1), local

    return evaluate
