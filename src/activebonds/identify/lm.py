"""Levenberg-Marquardt over a structured linear system: the outer loop, with optimistix's rules.

optimistix's ``LevenbergMarquardt`` solves each damped step from the dense Jacobian (QR of
``[J; sqrt(lambda) I]``). Where the Jacobian has a structure to exploit (multiple shooting:
:mod:`.shooting_normal`), the step is solved from the normal equations built by blocks, and
this loop drives it with the same rules, so the two paths take the same steps up to
rounding:

* the damping is ``lambda = 1 / step_size``, the step solves ``(J^T J + lambda I) d = -J^T r``;
* a step is accepted when the loss ``|r|^2 / 2`` falls by at least 1 % of the Gauss-Newton
  model's prediction; the step size grows 3.5 times when it falls by 99 % of it, shrinks 4
  times on a rejection (optimistix's ``ClassicalTrustRegion``);
* it stops after an accepted step that moved every variable by less than
  ``atol + rtol |y|`` and every residual by less than ``atol + rtol |r|`` (Cauchy
  termination, max norm), or at ``max_steps`` evaluations (the first being the start's).

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

LOW, HIGH = 0.01, 0.99  # share of the predicted reduction: accept / grow
GROW, SHRINK = 3.5, 0.25
PRECISION = 0.05  # standard deviations: a Gauss-Newton step shorter than this ends the solve
JITTER = 1e-12  # of the system's scale: the Gauss-Newton step's damping (unseen directions)


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
def _measures(grad, d, y_new, r, r_new, rtol, atol):
    """(the new loss, g . d, d . d, whether the step and the residuals' change are small)."""
    change = jax.tree.map(jnp.subtract, r_new, r)
    small = _small(d, y_new, rtol, atol) & _small(change, r_new, rtol, atol)
    return 0.5 * _dot(r_new, r_new), _dot(grad, d), _dot(d, d), small


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
):
    """Minimise ``|residual(y)|^2 / 2`` from ``y0`` (a pytree): ``linearize(y, r) -> (system,
    gradient J^T r)``, ``step(system, damping) -> d``. Returns (y, steps, message) as
    :func:`.refine._solve` does; ``on_step(steps, loss)`` after every evaluation;
    ``scale(system)``: the largest diagonal entry of J^T J, for the precision test (none
    without it); ``linear_enough(y)``: whether the Gauss-Newton model can be trusted that far
    at y (else the test waits: e.g. a variable whose transform is flat at a bound)."""
    y = y0
    r = residual(y)
    loss = 0.5 * float(_dot(r, r))
    unknowns = sum(leaf.size for leaf in jax.tree.leaves(y0))
    dof = max(1, sum(leaf.size for leaf in jax.tree.leaves(r)) - unknowns)
    system, grad = linearize(y, r)
    step_size = 1.0
    steps = 1
    if on_step:
        on_step(steps, loss)
    while steps < max_steps:
        damping = 1.0 / step_size
        d = step(system, damping)
        y_new = jax.tree.map(jnp.add, y, d)
        r_new = residual(y_new)
        loss_new, g_d, d_d, done = (
            float(x) for x in _measures(grad, d, y_new, r, r_new, rtol, atol)
        )
        steps += 1
        if on_step:
            on_step(steps, loss_new)
        predicted = 0.5 * g_d - 0.5 * damping * d_d  # g.d + d^T J^T J d / 2
        change = loss_new - loss if np.isfinite(loss_new) else np.inf
        accept = change <= LOW * predicted
        good = accept and predicted < 0 and change < HIGH * predicted
        step_size *= GROW if good else (1.0 if accept else SHRINK)
        if not accept:
            if step_size < 1e-300:
                return y, steps, "stopped: the damping grew without bound (no step lowers the cost)"
            continue
        y, r, loss = y_new, r_new, loss_new
        if done:
            return y, steps, "converged"
        system, grad = linearize(y, r)
        variance = 2.0 * loss / dof  # sigma^2
        trusted = linear_enough is None or linear_enough(y)
        if scale is not None and -change < 0.5 * variance and trusted:
            gauss_newton = step(system, JITTER * float(scale(system)))
            distance = -float(_dot(grad, gauss_newton)) / variance  # d^T J^T J d / sigma^2
            if distance < precision**2:
                return (
                    y,
                    steps,
                    (
                        f"converged to {precision:g} of a standard deviation "
                        "(a Gauss-Newton step would move the estimate less)"
                    ),
                )
    return y, steps, f"stopped at the step limit ({max_steps}) before converging"
