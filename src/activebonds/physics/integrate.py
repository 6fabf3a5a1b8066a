"""Time integration (DESIGN.md §2): semi-implicit Euler (default) or velocity Verlet, with
substeps h = dt / substeps; free-run rollouts (lax.scan over time) and one-step predictions.

Every function takes the time of its starting state (``t``, or ``t0`` for a rollout; seconds
from the first frame of the data window or of the simulation, default 0) and evaluates each
force at the time of its substep: ``t + k h`` for substep k, the second force of a Verlet
step at the step's end. Kinds that do not depend on time ignore it, so the compiled code of
a model without them does not change."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp

from .. import bonds
from ..model.params import Params, Topology
from . import linsolve, phase
from .forces import total_force
from .integrators import DEFAULT, EULER, VERLET
from .integrators import Integrator as Stepper

Integrator = str  # a scheme's name (:data:`activebonds.physics.integrators.SCHEMES`)


def stiff_kinds() -> frozenset[str]:
    """Kinds whose forces can be stiff in the velocity for a step (``stiff_in_velocity``: a
    contact's friction near sticking is a drag of ``mu Fn / eps``, eps = 1e-3 m/s,
    ``h mu Fn / (m eps)`` = 1-500 for steps of 0.05-5 ms). With substeps, their velocity
    dependence is taken implicitly (see :func:`kick`), and the start velocity is solved by
    Newton's method."""
    return frozenset(k.name for k in bonds.kinds() if k.stiff_in_velocity)


def stiff(topo: Topology) -> bool:
    """Whether a kind of :func:`stiff_kinds` is active in this topology."""
    return bool(stiff_kinds() & set(topo.active()))


def _stiff_jacobian(params: Params, topo: Topology, x, v, t):
    """[P, D, D] d F / d v_p of the stiff kinds on each particle: each of their bonds acts on
    one particle and depends on its velocity only, so the Jacobian is block-diagonal and D
    forward-mode directions (one velocity axis of every particle at once) give its blocks."""
    kinds = [k for k in topo.active() if k in stiff_kinds()]

    def f(v):
        out = jnp.zeros_like(x)
        for k in kinds:
            out = out + bonds.get(k).forces(params.bonds[k], topo.bonds[k], x, v, t)
        return out

    eye = jnp.eye(x.shape[1], dtype=x.dtype)
    cols = [jax.jvp(f, (v,), (jnp.broadcast_to(eye[d], x.shape),))[1] for d in range(x.shape[1])]
    return jnp.stack(cols, axis=-1)  # [P, D (force axis), D (velocity axis)]


def kick(params: Params, topo: Topology, x, v, h, force, t=0.0, implicit: bool = False):
    """The velocity change of a step of length h under ``force`` = F(x, v): ``h F / m``, or
    with ``implicit`` the linearly implicit kick ``(m I - h J)^-1 h F`` per particle, ``J``
    the stiff kinds' d F / d v (:func:`_stiff_jacobian`): the stiff drag's part of the force is
    then taken at the step's new velocity (to first order), so a sticking contact settles
    instead of chattering when ``h mu Fn / (m eps)`` exceeds 2 (explicit steps are unstable
    there). Where no stiff bond acts, J = 0 and the kick is the explicit one."""
    m = params.mass[:, None]
    if not implicit:
        return h * force / m
    dim = x.shape[1]
    jac = _stiff_jacobian(params, topo, x, v, t)
    system = m[..., None] * jnp.eye(dim, dtype=x.dtype) - h * jac  # [P, D, D]
    return jax.vmap(linsolve.solve)(system, h * force)  # not LAPACK: see linsolve


def euler_step(params: Params, topo: Topology, x, v, h, t=0.0, implicit: bool = False, psi=None):
    """Semi-implicit (symplectic) Euler: v <- v + h F(x, v, t)/m; x <- x + h v (the kick
    linearly implicit in the stiff kinds' velocity dependence with ``implicit``).

    ``psi``: an entrained drive's phase (:mod:`activebonds.physics.phase`), read by the
    forces and advanced by explicit Euler from the step's start, ``psi + h dpsi/dt(x, psi)``;
    then the step returns (x, v, psi)."""
    if psi is not None:
        p = phase.at_phase(params, psi)
        v = v + kick(p, topo, x, v, h, total_force(p, topo, x, v, t), t, implicit)
        return x + h * v, v, psi + h * phase.rate(params, topo, x, psi)
    v = v + kick(params, topo, x, v, h, total_force(params, topo, x, v, t), t, implicit)
    return x + h * v, v


def verlet_step(params: Params, topo: Topology, x, v, h, t=0.0, implicit: bool = False, psi=None):
    """Velocity Verlet. With velocity-dependent forces the second force uses the
    half-step velocity (exact Verlet when forces do not depend on velocity); it is
    evaluated at the step's end, t + h. ``implicit``: both half kicks as in
    :func:`euler_step`. ``psi``: as in :func:`euler_step` (the second force reads the
    step's end phase)."""
    if psi is not None:
        p = phase.at_phase(params, psi)
        v_half = v + kick(p, topo, x, v, 0.5 * h, total_force(p, topo, x, v, t), t, implicit)
        psi_end = psi + h * phase.rate(params, topo, x, psi)
        x = x + h * v_half
        p = phase.at_phase(params, psi_end)
        f_new = total_force(p, topo, x, v_half, t + h)
        return x, v_half + kick(p, topo, x, v_half, 0.5 * h, f_new, t + h, implicit), psi_end
    v_half = v + kick(params, topo, x, v, 0.5 * h, total_force(params, topo, x, v, t), t, implicit)
    x = x + h * v_half
    f_new = total_force(params, topo, x, v_half, t + h)
    return x, v_half + kick(params, topo, x, v_half, 0.5 * h, f_new, t + h, implicit)


def _needs_phase(topo: Topology, psi) -> None:
    if psi is None and phase.entrained(topo):
        raise ValueError(
            "the model's drive is entrained: its phase is a state, give psi (see "
            "activebonds.physics.phase.track for a recorded start)"
        )


STEPS: dict[str, Callable] = {EULER.name: euler_step, VERLET.name: verlet_step}


def advance(
    params: Params,
    topo: Topology,
    x,
    v,
    dt,
    substeps: int = 1,
    method: Integrator = DEFAULT,
    t=0.0,
    psi=None,
    unroll: bool = False,
):
    """Integrate over one sample interval dt in ``substeps`` steps, from time ``t``;
    returns (x, v), or (x, v, psi) with an entrained drive's phase ``psi`` (required then).

    ``unroll``: the substeps written out in the program (up to :data:`UNROLLED`) rather than
    run as a loop. Written out, a population's cost (vmapped over 100 genomes) runs 25-50 %
    faster; a loop traces in under half the time, compiles in 45-85 % and runs as fast for
    one trajectory, a Jacobian over the parameters and the shooting's normal equations by
    window (``benchmarks/substeps.py``), so it is the default. The dense shooting path (a
    forward-mode Jacobian over every window's state) keeps its substeps written out, as
    measured when it was chosen; measured again, the two forms were within the noise.

    With substeps (> 1) and a stiff kind (:func:`stiff_kinds`), every substep's kick is
    linearly implicit in that kind's velocity dependence (:func:`kick`): substeps exist to
    resolve fast dynamics, and an explicit kick cannot resolve a sticking contact's drag
    (stable only below ``h = 2 m eps / (mu Fn)``, about 20 us at a hopper's landing). One
    step per frame keeps the explicit kick, so the paper's one-step cost, its population
    form and the exact least squares are unchanged."""
    _needs_phase(topo, psi)
    step = STEPS[method]
    h = dt / substeps
    extra = () if psi is None else (psi,)  # the drive's phase rides with the state

    def one(state, tk, implicit=False):
        x, v, *rest = state
        return step(params, topo, x, v, h, tk, implicit, *rest)

    if substeps > 1 and stiff(topo):  # a loop, not unrolled: the kicks solve and differentiate

        def implicit(k, state):
            return one(state, t + k * h, True)

        return jax.lax.fori_loop(0, substeps, implicit, (x, v, *extra))
    if substeps == 1 or (unroll and substeps <= UNROLLED):
        state = (x, v, *extra)
        for k in range(substeps):
            state = one(state, t if k == 0 else t + k * h)
        return state

    def body(state, k):  # a loop, not unrolled: compile time independent of substeps
        return one(state, t + k * h), None

    state, _ = jax.lax.scan(body, one((x, v, *extra), t), jnp.arange(1, substeps))
    return state


UNROLLED = 8  # substeps written out in the program where asked (``unroll``); more: a loop
# fixed-point rounds of start_velocity (substeps > 1): the fixed point contracts by
# about dt (c/m + dt k/m) a round, 0.2-0.3 for a body's springs at 60 Hz (500 N/m, 5 N s/m per
# kg), so 3 rounds left every such start 1e-3 off (NaN: +inf cost, a shot model rejected) and
# 12 reach the 1e-6 tolerance up to a contraction of 0.3
START_ITERATIONS = 12
# ... and of its Newton's method (a stiff kind): quadratic, it stalls only at kinks
NEWTON_ITERATIONS = 3
START_TOLERANCE = 1e-6  # largest last residual, relative to the frame's displacement
START_ATOL = 1e-10  # m: ... plus this (a particle at rest has no displacement to be relative to)


def _landing_velocity(topo, substeps, method, params, x_prev, x, dt, t_prev, psi, v0):
    """The velocity ``v`` at ``x_prev`` whose interval (``substeps`` steps of ``method``)
    lands on ``x``, by Newton's method from ``v0`` on the exact Jacobian ``d x_end / d v``
    (forward mode over the P D velocity coordinates); its derivative by the implicit
    function theorem (``d v = -J^-1 d x_end|_v``), not through the rounds, so a forward-mode
    Jacobian of a cost over many parameters does not nest one Jacobian inside another."""

    def miss(v, params, x_prev, x, dt, t_prev, psi):
        return advance(params, topo, x_prev, v, dt, substeps, method, t_prev, psi)[0] - x

    def jacobian(v, *args):
        flat = jax.jacfwd(lambda vf: miss(vf.reshape(v.shape), *args).ravel())
        return flat(v.ravel())

    @jax.custom_jvp
    def solve(params, x_prev, x, dt, t_prev, psi, v0):
        args = (params, x_prev, x, dt, t_prev, psi)

        def round_(_, v):
            step = linsolve.solve(jacobian(v, *args), miss(v, *args).ravel())
            return v - step.reshape(v.shape)

        return jax.lax.fori_loop(0, NEWTON_ITERATIONS, round_, v0)

    @solve.defjvp
    def _(primals, tangents):
        v = solve(*primals)
        args, d_args = primals[:-1], tangents[:-1]
        _, d_miss = jax.jvp(lambda *a: miss(v, *a), args, d_args)
        d_v = -linsolve.solve(jacobian(v, *args), d_miss.ravel())
        return v, d_v.reshape(v.shape)

    return solve(params, x_prev, x, dt, t_prev, psi, v0)


def start_velocity(
    params: Params,
    topo: Topology,
    x_prev,
    x,
    dt,
    substeps: int = 1,
    method: Integrator = DEFAULT,
    iterations: int = START_ITERATIONS,
    t=0.0,
    with_residual: bool = False,
    psi=None,
    newton: bool = False,
    unroll: bool = False,
):
    """The velocity at a recorded frame that the integrator itself would carry there, given
    the two recorded positions ``x_prev`` (frame t - 1) and ``x`` (frame t); ``t`` is the
    time of frame t (``x_prev`` is at ``t - dt``). ``psi``: an entrained drive's phase at
    frame t - 1 (required then; the landing step advances it with the state).

    The backward difference ``v_b = (x - x_prev) / dt`` is the *mean* velocity over the last
    interval, i.e. the velocity about half a frame earlier. Only one-substep semi-implicit
    Euler carries exactly ``v_b`` (its position update is ``x_t = x_{t-1} + dt v_t``); feeding
    ``v_b`` to any other scheme makes every identified force come out inflated (about
    ``2N/(N+1)`` with N Euler substeps, about 2 with Verlet). So:

    * one Euler substep (:attr:`~.integrators.Integrator.exact_backward`): ``v_b`` (exact);
    * one Verlet substep: ``v_b + dt/2 a(x, v_b)`` (exact: ``v_b`` is its half-step velocity);
    * otherwise: the state at t - 1 whose step lands on ``x`` is solved for its velocity,
      started from the constant-acceleration estimate, and the velocity that step ends with
      is returned (corrected to first order by the last residual). The solve is a
      fixed-point iteration ``v <- v + (x - x_end) / dt`` (Newton's method with the
      Jacobian ``d x_end / d v`` taken as ``dt I``), contracting by about
      ``dt * (c/m + dt k/m)`` per round; on data the same scheme generated it recovers the
      true state to ``~ contraction^(iterations+1)``. Where a force is stiff in the velocity
      for the frame interval, that contraction exceeds 1 and the iteration diverges: a
      contact's friction near sticking is a drag of ``mu Fn / eps`` (``dt mu Fn / (m eps)``
      is 10-500 at 100-200 Hz). With a kind of :func:`stiff_kinds` the solve is therefore
      Newton's method on the exact Jacobian (forward mode over the P D velocity
      coordinates: about P D + 1 times a step's cost per round, quadratic convergence), the
      substeps' kicks being linearly implicit in that kind's drag (:func:`advance`).

    When a solve has converged, and what is returned where it has not: :func:`_solve_landing`.

    ``newton``: solve by Newton's method on the exact Jacobian for every kind (about P D + 1
    times a step's cost per round), differentiated implicitly (:func:`_landing_velocity`).
    The fixed point, cheap enough for a population, slows as its contraction nears 1 and
    diverges beyond: on a 41-marker spring body fitted to a real walk (2 Verlet substeps at
    60 Hz) it contracts by 0.67 a round, and its 12 rounds leave every start unsolved. The
    callers with one parameter vector try the fixed point first and take Newton's method
    where it failed (:meth:`activebonds.identify.solvers.refine.Refinement.to_newton`,
    :func:`activebonds.identify.judge.predictions.solved`); a population keeps the fixed point.

    ``with_residual``: also return the last residual where the solve has not converged (m;
    0 where it has or none is needed), for counting the starts that could not be solved.
    ``unroll``: the substeps written out (:func:`advance`).
    """
    _needs_phase(topo, psi)
    v_b = (x - x_prev) / dt
    stepper = Stepper(method, substeps)
    if stepper.exact_backward:
        return (v_b, jnp.zeros(())) if with_residual else v_b
    inv_m = 1.0 / params.mass[:, None]
    at_prev, at_t = params, params  # the forces' parameters at frames t - 1 and t
    if psi is not None:
        at_prev = phase.at_phase(params, psi)
        at_t = phase.at_phase(params, psi + dt * phase.rate(params, topo, x_prev, psi))
    if stepper.half_kick_start:
        v = v_b + 0.5 * dt * total_force(at_t, topo, x, v_b, t) * inv_m
        return (v, jnp.zeros(())) if with_residual else v
    # Constant acceleration a: Euler's N substeps start from v_b - dt (N+1)/(2N) a, Verlet's
    # from v_b - dt/2 a.
    lag = stepper.start_lag()
    t_prev = t - dt
    v = v_b - lag * dt * total_force(at_prev, topo, x_prev, v_b, t_prev) * inv_m

    v_out, residual = _solve_landing(
        params, topo, x_prev, x, v, dt, substeps, method, t_prev, psi, unroll, iterations, newton
    )
    return (v_out, residual) if with_residual else v_out


def _solve_landing(
    params, topo, x_prev, x, v, dt, substeps, method, t_prev, psi, unroll, iterations, newton
):
    """:func:`start_velocity`'s solve, from its estimate ``v`` at frame t - 1 (time
    ``t_prev``): (the velocity the landing step ends with, corrected to first order by the
    last residual; that residual where the solve has not converged, else 0).

    A solve has converged when its last residual is at most ``START_TOLERANCE`` of the
    frame's displacement plus ``START_ATOL``. Where it has not, the velocity is NaN, so such
    a candidate costs +inf and is counted as failed rather than silently biased; with a stiff
    kind, whose landing map has kinks (a contact starting, ending or sticking within the
    frame) where Newton's method can stall, it is the last iterate's (corrected to first
    order by its residual, a few micrometres in such frames): the fit counts these starts
    and says so (:func:`activebonds.identify.costs.windows.unsolved_starts`)."""

    def land(v):
        return advance(params, topo, x_prev, v, dt, substeps, method, t_prev, psi, unroll)[:2]

    if newton and not stiff(topo):
        v = _landing_velocity(topo, substeps, method, params, x_prev, x, dt, t_prev, psi, v)
    elif stiff(topo):

        def land_flat(vf):  # (x_end flat, x_end)
            x_end = land(vf.reshape(x.shape))[0]
            return x_end.ravel(), x_end

        jac = jax.jacfwd(land_flat, has_aux=True)

        def newton(_, v):
            j, x_end = jac(v.ravel())
            return v + linsolve.solve(j, (x - x_end).ravel()).reshape(x.shape)

        v = jax.lax.fori_loop(0, min(iterations, NEWTON_ITERATIONS), newton, v)
    else:  # a loop, not unrolled: compile time independent of the rounds

        def fixed_point(_, v):
            return v + (x - land(v)[0]) / dt

        v = jax.lax.fori_loop(0, iterations, fixed_point, v)
    x_end, v_end = land(v)
    residual = jnp.sqrt(jnp.sum((x - x_end) ** 2))
    scale = jnp.sqrt(jnp.sum((x - x_prev) ** 2))
    converged = residual <= START_TOLERANCE * scale + START_ATOL
    v_out = v_end + (x - x_end) / dt
    if not stiff(topo):
        v_out = jnp.where(converged, v_out, jnp.nan)
    return v_out, jnp.where(converged, 0.0, residual)


def rollout(
    params: Params,
    topo: Topology,
    x0,
    v0,
    dt,
    n_frames: int,
    substeps: int = 1,
    method: Integrator = DEFAULT,
    t0=0.0,
    psi0=None,
):
    """Free run: positions of ``n_frames`` frames, the first being x0 (at time ``t0``).
    Shape [n_frames, P, D]. With an entrained drive's phase ``psi0`` at x0 (required then):
    (positions, phases [n_frames])."""
    _needs_phase(topo, psi0)
    if psi0 is not None:

        def phased(state, i):
            x, v, psi = state
            state = advance(params, topo, x, v, dt, substeps, method, t0 + i * dt, psi)
            return state, (state[0], state[2])

        _, (xs, psis) = jax.lax.scan(phased, (x0, v0, psi0), jnp.arange(n_frames - 1))
        psi0 = jnp.asarray(psi0, psis.dtype)
        return jnp.concatenate([x0[None], xs]), jnp.concatenate([psi0[None], psis])

    def body(state, i):
        x, v = advance(params, topo, *state, dt, substeps, method, t0 + i * dt)
        return (x, v), x

    _, xs = jax.lax.scan(body, (x0, v0), jnp.arange(n_frames - 1))
    return jnp.concatenate([x0[None], xs], axis=0)


def rollout_states(
    params,
    topo,
    x0,
    v0,
    dt,
    n_steps: int,
    substeps: int = 1,
    method=DEFAULT,
    t0=0.0,
    psi0=None,
    unroll: bool = False,
):
    """Free run returning (positions, velocities) of the ``n_steps`` states after (x0, v0),
    (x0, v0) being at time ``t0``; with an entrained drive's phase ``psi0`` at x0 (required
    then), (positions, velocities, phases). ``unroll``: the substeps written out
    (:func:`advance`)."""
    _needs_phase(topo, psi0)
    if psi0 is not None:

        def phased(state, i):
            x, v, psi = state
            state = advance(params, topo, x, v, dt, substeps, method, t0 + i * dt, psi, unroll)
            return state, state

        _, states = jax.lax.scan(phased, (x0, v0, psi0), jnp.arange(n_steps))
        return states

    def body(state, i):
        state = advance(params, topo, *state, dt, substeps, method, t0 + i * dt, unroll=unroll)
        return state, state

    _, (xs, vs) = jax.lax.scan(body, (x0, v0), jnp.arange(n_steps))
    return xs, vs
