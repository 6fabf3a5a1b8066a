"""Time integration (DESIGN.md §2): semi-implicit Euler (default) or velocity Verlet, with
substeps h = dt / substeps; free-run rollouts (lax.scan over time) and one-step predictions.

Every function takes the time of its starting state (``t``, or ``t0`` for a rollout; seconds
from the first frame of the data window or of the simulation, default 0) and evaluates each
force at the time of its substep: ``t + k h`` for substep k, the second force of a Verlet
step at the step's end. Kinds that do not depend on time ignore it, so the compiled code of
a model without them does not change."""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

import jax
import jax.numpy as jnp

from ..model.params import Params, Topology
from .forces import total_force

Integrator = Literal["euler", "verlet"]


def euler_step(params: Params, topo: Topology, x, v, h, t=0.0):
    """Semi-implicit (symplectic) Euler: v <- v + h F(x, v, t)/m; x <- x + h v."""
    acc = total_force(params, topo, x, v, t) / params.mass[:, None]
    v = v + h * acc
    return x + h * v, v


def verlet_step(params: Params, topo: Topology, x, v, h, t=0.0):
    """Velocity Verlet. With velocity-dependent forces the second force uses the
    half-step velocity (exact Verlet when forces do not depend on velocity); it is
    evaluated at the step's end, t + h."""
    inv_m = 1.0 / params.mass[:, None]
    acc = total_force(params, topo, x, v, t) * inv_m
    v_half = v + 0.5 * h * acc
    x = x + h * v_half
    acc_new = total_force(params, topo, x, v_half, t + h) * inv_m
    return x, v_half + 0.5 * h * acc_new


STEPS: dict[str, Callable] = {"euler": euler_step, "verlet": verlet_step}


def advance(
    params: Params,
    topo: Topology,
    x,
    v,
    dt,
    substeps: int = 1,
    method: Integrator = "euler",
    t=0.0,
):
    """Integrate over one sample interval dt in ``substeps`` steps, from time ``t``."""
    step = STEPS[method]
    h = dt / substeps
    if substeps <= UNROLLED:
        for k in range(substeps):
            x, v = step(params, topo, x, v, h, t if k == 0 else t + k * h)
        return x, v

    def body(state, k):  # a loop, not unrolled: compile time independent of substeps
        return step(params, topo, *state, h, t + k * h), None

    (x, v), _ = jax.lax.scan(body, step(params, topo, x, v, h, t), jnp.arange(1, substeps))
    return x, v


UNROLLED = 2  # substeps written out in the program; more run as a loop
START_ITERATIONS = 3  # fixed-point iterations of start_velocity (substeps > 1)
START_TOLERANCE = 1e-6  # largest last residual, relative to the frame's displacement


def start_velocity(
    params: Params,
    topo: Topology,
    x_prev,
    x,
    dt,
    substeps: int = 1,
    method: Integrator = "euler",
    iterations: int = START_ITERATIONS,
    t=0.0,
):
    """The velocity at a recorded frame that the integrator itself would carry there, given
    the two recorded positions ``x_prev`` (frame t - 1) and ``x`` (frame t); ``t`` is the
    time of frame t (``x_prev`` is at ``t - dt``).

    The backward difference ``v_b = (x - x_prev) / dt`` is the *mean* velocity over the last
    interval, i.e. the velocity about half a frame earlier. Only one-substep semi-implicit
    Euler carries exactly ``v_b`` (its position update is ``x_t = x_{t-1} + dt v_t``); feeding
    ``v_b`` to any other scheme makes every identified force come out inflated (about
    ``2N/(N+1)`` with N Euler substeps, about 2 with Verlet). So:

    * Euler, one substep: ``v_b`` (exact);
    * Verlet, one substep: ``v_b + dt/2 a(x, v_b)`` (exact: ``v_b`` is the step's half-step
      velocity, and the step closes with ``+ dt/2 a(x_t, v_half)``);
    * otherwise: the state at t - 1 whose step lands on ``x`` is solved by a fixed-point
      iteration on its velocity (``v <- v + (x - x_end) / dt``, contracting by about
      ``dt * (c/m + dt k/m)`` per round, started from the constant-acceleration estimate)
      and the velocity that step ends with is returned (corrected to first order by the last
      residual). On data the same scheme generated, this recovers the true state to
      ``~ contraction^(iterations+1)``. Where it has not converged (a last residual above
      ``START_TOLERANCE`` of the frame's displacement: stiff or heavily damped parameters for
      the frame interval) the velocity is NaN, so such a candidate costs +inf and is counted
      as failed rather than silently biased.
    """
    v_b = (x - x_prev) / dt
    if substeps == 1 and method == "euler":
        return v_b
    inv_m = 1.0 / params.mass[:, None]
    if substeps == 1 and method == "verlet":
        return v_b + 0.5 * dt * total_force(params, topo, x, v_b, t) * inv_m
    # Constant acceleration a: Euler's N substeps start from v_b - dt (N+1)/(2N) a, Verlet's
    # from v_b - dt/2 a.
    lag = 0.5 * (substeps + 1) / substeps if method == "euler" else 0.5
    t_prev = t - dt
    v = v_b - lag * dt * total_force(params, topo, x_prev, v_b, t_prev) * inv_m
    for _ in range(iterations):
        x_end, v_end = advance(params, topo, x_prev, v, dt, substeps, method, t_prev)
        v = v + (x - x_end) / dt
    x_end, v_end = advance(params, topo, x_prev, v, dt, substeps, method, t_prev)
    residual = jnp.sqrt(jnp.sum((x - x_end) ** 2))
    scale = jnp.sqrt(jnp.sum((x - x_prev) ** 2)) + 1e-12
    converged = residual <= START_TOLERANCE * scale
    return jnp.where(converged, v_end + (x - x_end) / dt, jnp.nan)


def rollout(
    params: Params,
    topo: Topology,
    x0,
    v0,
    dt,
    n_frames: int,
    substeps: int = 1,
    method: Integrator = "euler",
    t0=0.0,
):
    """Free run: positions of ``n_frames`` frames, the first being x0 (at time ``t0``).
    Shape [n_frames, P, D]."""

    def body(state, i):
        x, v = advance(params, topo, *state, dt, substeps, method, t0 + i * dt)
        return (x, v), x

    _, xs = jax.lax.scan(body, (x0, v0), jnp.arange(n_frames - 1))
    return jnp.concatenate([x0[None], xs], axis=0)


def rollout_states(
    params, topo, x0, v0, dt, n_steps: int, substeps: int = 1, method="euler", t0=0.0
):
    """Free run returning (positions, velocities) of the ``n_steps`` states after (x0, v0),
    (x0, v0) being at time ``t0``."""

    def body(state, i):
        state = advance(params, topo, *state, dt, substeps, method, t0 + i * dt)
        return state, state

    _, (xs, vs) = jax.lax.scan(body, (x0, v0), jnp.arange(n_steps))
    return xs, vs
