"""Levenberg-Marquardt inside a box: an active set for the bounds, projected steps, and a
stop where the model sees nothing left to gain.

The sine transform (:class:`.stage.Bounded`) keeps every step inside the bounds by making the
loss flat at them: a gene pressed against its bound has ``d gene / d u = 0``, the step can
move it only by a vanishing amount, its curvature vanishes in J^T J, and a Gauss-Newton step
in u there means little (:mod:`.lm` waits for the precision test until every gene is off its
bounds). On a large body with many genes at their bounds (the spring body on the bundled walk:
111 of 414 genes within 1 % of a bound) the refinement crawls: hundreds of accepted steps
that lower the loss by parts in a million. Here the genes are the unknowns themselves
(:class:`Box`: the identity), and the bounds are kept by an active set, after Bertsekas'
projected Newton method (D. P. Bertsekas 1982, "Projected Newton methods for optimization
problems with simple constraints", SIAM J. Control Optim. 20:221-246) with the
Levenberg-Marquardt step projected onto the box as in Kanzow, Yamashita & Fukushima (2004,
"Levenberg-Marquardt methods with strong local convergence properties for solving nonlinear
equations with convex constraints", J. Comput. Appl. Math. 172:375-397):

* a variable on a bound (within :data:`EDGE` of its span) whose gradient points out of the box
  is *held*: it gets a damping :data:`HOLD` times the system's largest diagonal and its step
  is set to 0, which is removing its row and column from the normal equations without
  changing their structure (the Schur complement of a shooting stage's states keeps its
  blocks); it is released as soon as its gradient turns inward;
* the step of the free variables is projected onto the box (``clip(y + d)``), and the model's
  prediction is that of the step actually taken, ``g.d + d^T A d / 2`` (A the model's matrix:
  J^T J, or J^T J + S with :mod:`.hybrid`'s secant term); acceptance and the damping then
  follow :mod:`.lm`'s rules (optimistix's 1 %, Nielsen's update, Marquardt's scaling);
* the precision test of :mod:`.lm` (a Gauss-Newton step, the held variables held, shorter than
  0.05 standard deviations ends the stage) needs no wait at the bounds any more.

One more stopping rule: when :data:`FLAT_STEPS` trial steps in a row each predicted less
gain than ``PRECISION^2 sigma^2 / 2`` (sigma^2 = 2 loss / (residuals - unknowns), the
residuals' variance), the stage ends, its message saying so. A gain of ``d^2 sigma^2 / 2``
is what moving the estimate d standard deviations in the metric of its covariance is worth
(:mod:`.lm`), so each of those steps was worth less than a twentieth of a standard deviation;
at that rate even the 500 steps of a stage's limit would move the estimate about one
standard deviation. The precision test asks the undamped step; this rule asks the steps the
solver actually takes, so it also ends a stage whose damping keeps every step short (and a
stage started at its optimum, within a few steps).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

from .lm import JITTER, LOW, PRECISION, STALLED, Interrupted, _dot, _larger, _small

EDGE = 1e-10  # of a bound's span: a variable this close to its bound is on it
HOLD = 1e16  # of the system's largest diagonal entry: the damping of a held variable
FLAT_STEPS = 3  # trial steps in a row predicting less than the precision's gain end a stage


class Box:
    """The box of the genes as the search space itself (the identity; :class:`.stage.Bounded`
    for the sine transform): ``box`` the (lower, upper) the solver keeps."""

    def __init__(self, lower, upper):
        self.lower = np.asarray(lower, np.float64)
        self.upper = np.asarray(upper, np.float64)
        self.span = self.upper - self.lower
        self.box = (self.lower, self.upper)

    def to_genome(self, u):
        return u

    def from_genome(self, genome):
        return np.clip(np.asarray(genome, np.float64), self.lower, self.upper)

    def interior(self, u) -> bool:
        """The Gauss-Newton model holds at a bound too (the active set): always True."""
        return True

    def inside(self, genome) -> bool:
        g = np.asarray(genome)
        return bool(np.all((g >= self.lower) & (g <= self.upper)))


def flat_message(share: float) -> str:
    return (
        f"stopped: the model predicts less than {share:.2g} of the cost can still be gained "
        f"({FLAT_STEPS} steps in a row, each worth under {PRECISION:g} of a standard deviation)"
    )


@jax.jit
def _held(y, grad, lower, upper):
    """Variables on a bound whose gradient points out of the box (a pytree of booleans)."""

    def leaf(x, g, lo, hi):
        span = hi - lo
        tol = jnp.where(jnp.isfinite(span), EDGE * span, 0.0)
        return ((x <= lo + tol) & (g > 0)) | ((x >= hi - tol) & (g < 0))

    return jax.tree.map(leaf, y, grad, lower, upper)


@jax.jit
def _damping(damping, scaling, hold, big):
    """The diagonal of the damping: ``damping * scaling``, ``big`` where held."""
    return jax.tree.map(lambda s, h: jnp.where(h, big, damping * s), scaling, hold)


@jax.jit
def _project(y, d, hold, lower, upper):
    """(the projected point, the step taken to it)."""
    d = jax.tree.map(lambda x, h: jnp.where(h, 0.0, x), d, hold)
    new = jax.tree.map(lambda a, b, lo, hi: jnp.clip(a + b, lo, hi), y, d, lower, upper)
    return new, jax.tree.map(jnp.subtract, new, y)


@jax.jit
def _measures(grad, d, y_new, r, r_new, rtol, atol):
    change = jax.tree.map(jnp.subtract, r_new, r)
    small = _small(d, y_new, rtol, atol) & _small(change, r_new, rtol, atol)
    return 0.5 * _dot(r_new, r_new), _dot(grad, d), small


def _prepare(scaling, secant, system, r) -> None:
    """The programs of an accepted step compiled now, whether or not a step is accepted: a
    solve of these shapes compiles the same programs whichever path it takes."""
    _larger(scaling, scaling)
    if secant is not None:
        secant.prepare(system, r)


def box_levenberg_marquardt(
    residual: Callable,
    linearize: Callable,
    step: Callable,
    curvature: Callable,
    y0,
    lower,
    upper,
    max_steps: int,
    rtol: float,
    atol: float,
    on_step: Callable[[int, float], None] | None = None,
    scale: Callable | None = None,
    precision: float = PRECISION,
    diagonal: Callable | None = None,
    damping: float = 1.0,
    stop: Callable[[], bool] | None = None,
    secant=None,
):
    """Minimise ``|residual(y)|^2 / 2`` over the box ``lower <= y <= upper`` (pytrees like y;
    +-inf where unbounded) from ``y0``: as :func:`.lm.levenberg_marquardt` (same arguments,
    same result (y, steps, message)), with ``curvature(system, d) -> d^T A d`` for the
    prediction of a projected step; ``diagonal`` is required (Marquardt's scaling);
    ``secant``: a :class:`.hybrid.Hybrid` (dense systems only), else Gauss-Newton's model."""
    if stop is None:
        from ...runtime import stop_requested as stop
    lower, upper, y, r, loss, dof = _start(residual, y0, lower, upper)
    system, grad = linearize(y, r)
    scaling = diagonal(system)
    _prepare(scaling, secant, system, r)
    hold = _held(y, grad, lower, upper)
    nu, steps, flat = 2.0, 1, 0
    if on_step:
        on_step(steps, loss)
    while steps < max_steps:
        if stop():
            raise Interrupted(y, steps)
        big = HOLD * float(scale(system)) if scale is not None else HOLD
        model, d = _trial(system, secant, step, _damping(damping, scaling, hold, big))
        y_new, taken = _project(y, d, hold, lower, upper)
        r_new = residual(y_new)
        loss_new, g_d, done = (
            float(x) for x in _measures(grad, taken, y_new, r, r_new, rtol, atol)
        )
        steps += 1
        if on_step:
            on_step(steps, loss_new)
        predicted = g_d + 0.5 * float(curvature(model, taken))
        threshold = 0.5 * precision**2 * (2.0 * loss / dof)
        flat = _flat(flat, predicted, threshold)
        change = loss_new - loss if np.isfinite(loss_new) else np.inf
        accept = predicted < 0 and change <= LOW * predicted
        if not accept:
            damping, nu = damping * nu, 2.0 * nu
            if flat >= FLAT_STEPS:
                return y, steps, flat_message(threshold / loss if loss > 0 else 0.0)
            if damping > 1e300:
                return y, steps, STALLED
            continue
        rho = change / predicted
        damping *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
        nu = 2.0
        new_system, new_grad = (None, None) if done else linearize(y_new, r_new)
        if secant is not None and new_system is not None:
            secant.update(system, new_system, taken, r_new, change)
        y, r, loss = y_new, r_new, loss_new
        if done:
            return y, steps, "converged"
        system, grad = new_system, new_grad
        scaling = _larger(scaling, diagonal(system))  # MINPACK's rule
        hold = _held(y, grad, lower, upper)
        if flat >= FLAT_STEPS:
            return y, steps, flat_message(threshold / max(loss, 1e-300))
        variance = 2.0 * loss / dof
        if scale is not None and -change < 0.5 * variance:
            jitter = JITTER * float(scale(system))
            if _precise(system, grad, step, hold, scaling, jitter, big, variance, precision):
                return y, steps, PRECISE.format(precision)
    return y, steps, f"stopped at the step limit ({max_steps}) before converging"


PRECISE = (
    "converged to {:g} of a standard deviation (a Gauss-Newton step, the genes on their "
    "bounds held, would move the estimate less)"
)


def _start(residual, y0, lower, upper):
    """(lower, upper, the start clipped to them, its residuals, loss, degrees of freedom)."""
    lower = jax.tree.map(jnp.asarray, lower)
    upper = jax.tree.map(jnp.asarray, upper)
    y = jax.tree.map(lambda x, lo, hi: jnp.clip(jnp.asarray(x), lo, hi), y0, lower, upper)
    r = residual(y)
    unknowns = sum(leaf.size for leaf in jax.tree.leaves(y0))
    dof = max(1, sum(leaf.size for leaf in jax.tree.leaves(r)) - unknowns)
    return lower, upper, y, r, 0.5 * float(_dot(r, r)), dof


def _flat(flat: int, predicted: float, threshold: float) -> int:
    """Trial steps in a row whose predicted gain is under ``threshold`` (a step predicting a
    real gain resets the count)."""
    if abs(predicted) < threshold or not np.isfinite(predicted):
        return flat + 1
    return 0 if predicted < 0 else flat


def _trial(system, secant, step, damp):
    """(the model the step is solved on, the step): the hybrid's choice where there is one,
    Gauss-Newton's where its step is not finite."""
    model = system if secant is None else secant.model(system)
    d = step(model, damp)
    if secant is not None and model is not system and not _finite(d):
        secant.fallback()
        model, d = system, step(system, damp)
    return model, d


def _precise(system, grad, step, hold, scaling, jitter, big, variance, precision) -> bool:
    """Whether a Gauss-Newton step, the held genes held, would move the estimate by less than
    ``precision`` standard deviations (the precision test of :mod:`.lm`)."""
    gauss_newton = step(system, _damping(jitter, jax.tree.map(jnp.ones_like, scaling), hold, big))
    gauss_newton = jax.tree.map(lambda x, h: jnp.where(h, 0.0, x), gauss_newton, hold)
    return -float(_dot(grad, gauss_newton)) / variance < precision**2


def _finite(tree) -> bool:
    return bool(all(jnp.all(jnp.isfinite(leaf)) for leaf in jax.tree.leaves(tree)))
