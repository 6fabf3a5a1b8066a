"""Time integration (DESIGN.md §2): semi-implicit Euler (default) or velocity Verlet, with
substeps h = dt / substeps; free-run rollouts (lax.scan over time) and one-step predictions."""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

import jax
import jax.numpy as jnp

from ..model.params import Params, Topology
from .forces import total_force

Integrator = Literal["euler", "verlet"]


def euler_step(params: Params, topo: Topology, x, v, h):
    """Semi-implicit (symplectic) Euler: v <- v + h F/m; x <- x + h v."""
    acc = total_force(params, topo, x, v) / params.mass[:, None]
    v = v + h * acc
    return x + h * v, v


def verlet_step(params: Params, topo: Topology, x, v, h):
    """Velocity Verlet. With velocity-dependent forces the second force uses the
    half-step velocity (exact Verlet when forces do not depend on velocity)."""
    inv_m = 1.0 / params.mass[:, None]
    acc = total_force(params, topo, x, v) * inv_m
    v_half = v + 0.5 * h * acc
    x = x + h * v_half
    acc_new = total_force(params, topo, x, v_half) * inv_m
    return x, v_half + 0.5 * h * acc_new


STEPS: dict[str, Callable] = {"euler": euler_step, "verlet": verlet_step}


def advance(
    params: Params, topo: Topology, x, v, dt, substeps: int = 1, method: Integrator = "euler"
):
    """Integrate over one sample interval dt in ``substeps`` steps."""
    step = STEPS[method]
    h = dt / substeps
    for _ in range(substeps):
        x, v = step(params, topo, x, v, h)
    return x, v


def rollout(
    params: Params,
    topo: Topology,
    x0,
    v0,
    dt,
    n_frames: int,
    substeps: int = 1,
    method: Integrator = "euler",
):
    """Free run: positions of ``n_frames`` frames, the first being x0. Shape [n_frames, P, D]."""

    def body(state, _):
        x, v = advance(params, topo, *state, dt, substeps, method)
        return (x, v), x

    _, xs = jax.lax.scan(body, (x0, v0), None, length=n_frames - 1)
    return jnp.concatenate([x0[None], xs], axis=0)


def rollout_states(params, topo, x0, v0, dt, n_steps: int, substeps: int = 1, method="euler"):
    """Free run returning (positions, velocities) of the ``n_steps`` states after (x0, v0)."""

    def body(state, _):
        state = advance(params, topo, *state, dt, substeps, method)
        return state, state

    _, (xs, vs) = jax.lax.scan(body, (x0, v0), None, length=n_steps)
    return xs, vs
