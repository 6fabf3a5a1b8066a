"""Levenberg-Marquardt over a structured linear system: the outer loop, with Ceres Solver's
damping rules.

optimistix's ``LevenbergMarquardt`` solves each damped step from the dense Jacobian (QR of
``[J; sqrt(lambda) I]``). Where the Jacobian has a structure to exploit (multiple shooting:
:mod:`.shooting_normal`), the step is solved from the normal equations built by blocks, and
this loop drives it. It ends at the same optimum as optimistix (``tests/test_shooting_normal.py``
compares them in standard errors), by fewer steps:

* the damping ``lambda`` starts at ``damping``; the step solves ``(J^T J + lambda D) d =
  -J^T r``, D = I, or with ``diagonal`` Marquardt's scaling as MINPACK keeps it (More 1978):
  D the largest diagonal of J^T J met so far, entry by entry, so the damping weighs each
  variable by its own curvature whatever its units (Ceres Solver scales by J^T J's diagonal
  too), and a variable whose curvature vanishes on the way (a bound's sine transform turning
  flat) keeps the damping it had;
* a step is accepted when the loss ``|r|^2 / 2`` falls by at least 1 % of the Gauss-Newton
  model's prediction (optimistix's rule);
* the damping follows the actual-to-predicted reduction rho as Ceres Solver's
  Levenberg-Marquardt does (Nielsen's rule, Madsen, Nielsen & Tingleff 2004, eq. 3.16):
  after an accepted step it is multiplied by ``max(1/3, 1 - (2 rho - 1)^3)``, after a
  rejection by ``nu`` with ``nu`` doubling on each rejection in a row (2 after an accepted
  step). optimistix's classical trust region shrinks the damping only where rho > 0.99, so
  on a mildly nonlinear problem (rho 0.9-0.99 step after step) it keeps a damping that holds
  every step short: a shooting stage on the MuJoCo tetrahedron took 119 steps, 33 with
  these rules and Marquardt's scaling (``benchmarks/shooting.py``);
* it stops after an accepted step that moved every variable by less than
  ``atol + rtol |y|`` and every residual by less than ``atol + rtol |r|`` (Cauchy
  termination, max norm), or at ``max_steps`` evaluations (the first being the start's).

Between two steps it asks ``stop()`` (default :func:`activebonds.runtime.stop_requested`: the
command line's Ctrl-C) whether to stop; if so it raises :class:`Interrupted`, a
``KeyboardInterrupt`` that carries the last accepted point and the steps taken, so the caller
can save them. A long solve thus stops within one step of a Ctrl-C.

One rule of ours is added, where the caller gives the system's ``scale``: it also stops
when the estimate is known to a small fraction of its own uncertainty. The undamped
(Gauss-Newton) step d = -(J^T J)^-1 J^T r is d^T J^T J d / sigma^2 standard deviations
squared from the estimate in the metric of its covariance sigma^2 (J^T J)^-1, with sigma^2 =
|r|^2 / (residuals - unknowns) the residuals' own variance; once it is under ``precision``
(0.05: a twentieth of a standard deviation, far inside any confidence interval), further steps
cannot change what the fit says. On a large problem whose optimum lies in a long curved
valley (a 41-marker body) this ends in tens of steps a crawl that the Cauchy test lets run
to the step limit. The check costs one more solve, made only after an accepted step that
lowered the loss by less than sigma^2 / 2 (the loss of moving one standard deviation).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

LOW = 0.01  # share of the predicted reduction that accepts a step
PRECISION = 0.05  # standard deviations: a Gauss-Newton step shorter than this ends the solve
JITTER = 1e-12  # of the system's scale: the Gauss-Newton step's damping (unseen directions)


class Interrupted(KeyboardInterrupt):
    """A stop asked between two steps: ``value`` the last accepted point, ``steps`` the
    evaluations made."""

    def __init__(self, value, steps: int):
        super().__init__(f"interrupted after {steps} Levenberg-Marquardt steps")
        self.value, self.steps = value, steps


# why a refinement stopped where no step lowers the cost (the solver's damping, not the model's)
STALLED = "stopped: the Levenberg-Marquardt damping grew without bound (no step lowers the cost)"


def _dot(a, b):
    return sum(jnp.vdot(x, y) for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True))


def _small(diff, ref, rtol, atol):
    return jnp.all(
        jnp.stack(
            [
                jnp.all(jnp.abs(d) < atol + rtol * jnp.abs(r))
                for d, r in zip(jax.tree.leaves(diff), jax.tree.leaves(ref), strict=True)
            ]
        )
    )


@jax.jit
def _measures(grad, d, y_new, r, r_new, rtol, atol, scaling=None):
    """(the new loss, g . d, d^T D d (D = I without ``scaling``), whether the step and the
    residuals' change are small)."""
    change = jax.tree.map(jnp.subtract, r_new, r)
    small = _small(d, y_new, rtol, atol) & _small(change, r_new, rtol, atol)
    dd = _dot(d, d) if scaling is None else _dot(d, jax.tree.map(jnp.multiply, scaling, d))
    return 0.5 * _dot(r_new, r_new), _dot(grad, d), dd, small


def levenberg_marquardt(
    residual: Callable,
    linearize: Callable,
    step: Callable,
    y0,
    max_steps: int,
    rtol: float,
    atol: float,
    on_step: Callable[[int, float], None] | None = None,
    scale: Callable | None = None,
    precision: float = PRECISION,
    linear_enough: Callable | None = None,
    diagonal: Callable | None = None,
    damping: float = 1.0,
    stop: Callable[[], bool] | None = None,
):
    """Minimise ``|residual(y)|^2 / 2`` from ``y0`` (a pytree): ``linearize(y, r) -> (system,
    gradient J^T r)``, ``step(system, damping) -> d`` (``damping`` a number, times I, or a
    pytree like y: a diagonal). Returns (y, steps, message) as :func:`.stage.solve` does;
    ``on_step(steps, loss)`` after every evaluation; ``scale(system)``: the largest diagonal
    entry of J^T J, for the precision test (none without it); ``linear_enough(y)``: whether
    the Gauss-Newton model can be trusted that far at y (else the test waits: e.g. a variable
    whose transform is flat at a bound); ``diagonal(system)``: J^T J's diagonal (a pytree like
    y), for Marquardt's scaling D (without it, D = I). ``stop()``: asked between two steps
    (default: :func:`activebonds.runtime.stop_requested`); True raises :class:`Interrupted`
    with the last accepted point."""
    if stop is None:
        from ...runtime import stop_requested as stop
    y = y0
    r = residual(y)
    loss = 0.5 * float(_dot(r, r))
    unknowns = sum(leaf.size for leaf in jax.tree.leaves(y0))
    dof = max(1, sum(leaf.size for leaf in jax.tree.leaves(r)) - unknowns)
    system, grad = linearize(y, r)
    scaling = None if diagonal is None else diagonal(system)
    nu = 2.0
    steps = 1
    if on_step:
        on_step(steps, loss)
    while steps < max_steps:
        if stop():
            raise Interrupted(y, steps)
        d = step(system, damping if scaling is None else _times(damping, scaling))
        y_new = jax.tree.map(jnp.add, y, d)
        r_new = residual(y_new)
        loss_new, g_d, d_d, done = (
            float(x) for x in _measures(grad, d, y_new, r, r_new, rtol, atol, scaling)
        )
        steps += 1
        if on_step:
            on_step(steps, loss_new)
        predicted = 0.5 * g_d - 0.5 * damping * d_d  # g.d + d^T J^T J d / 2
        change = loss_new - loss if np.isfinite(loss_new) else np.inf
        accept = predicted < 0 and change <= LOW * predicted
        if not accept:
            damping, nu = damping * nu, 2.0 * nu
            if damping > 1e300:
                return y, steps, STALLED
            continue
        rho = change / predicted
        damping *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
        nu = 2.0
        y, r, loss = y_new, r_new, loss_new
        if done:
            return y, steps, "converged"
        system, grad = linearize(y, r)
        if scaling is not None:  # MINPACK's rule: D never shrinks (More 1978)
            scaling = _larger(scaling, diagonal(system))
        if _precise(
            y, loss, change, dof, system, grad, scaling, step, scale, linear_enough, precision
        ):
            return (
                y,
                steps,
                (
                    f"converged to {precision:g} of a standard deviation "
                    "(a Gauss-Newton step would move the estimate less)"
                ),
            )
    return y, steps, f"stopped at the step limit ({max_steps}) before converging"


def _precise(y, loss, change, dof, system, grad, scaling, step, scale, linear_enough, precision):
    """:func:`levenberg_marquardt`'s precision test at an accepted point ``y`` (its ``loss``,
    the step's ``change`` of it, the linearisation ``system`` and ``grad``): where the step
    lowered the cost by less than half the residuals' variance and the Gauss-Newton model is
    trusted there, whether a Gauss-Newton step would move the estimate less than
    ``precision`` of a standard deviation (False without ``scale``)."""
    variance = 2.0 * loss / dof  # sigma^2
    trusted = linear_enough is None or linear_enough(y)
    if not (scale is not None and -change < 0.5 * variance and trusted):
        return False
    jitter = JITTER * float(scale(system))
    if scaling is not None:  # as a diagonal: the step's program compiled once
        jitter = _times(jitter, jax.tree.map(jnp.ones_like, scaling))
    gauss_newton = step(system, jitter)
    distance = -float(_dot(grad, gauss_newton)) / variance  # d^T J^T J d / sigma^2
    return distance < precision**2


@jax.jit
def _larger(a, b):
    """The larger of two pytrees, leaf by leaf (one program, not an eager one a leaf)."""
    return jax.tree.map(jnp.maximum, a, b)


@jax.jit
def _times(damping, scaling):
    return jax.tree.map(lambda s: damping * s, scaling)
