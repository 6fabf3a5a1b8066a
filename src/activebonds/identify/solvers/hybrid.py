"""NL2SOL's adaptive model of a least-squares loss: Gauss-Newton, or Gauss-Newton plus a
secant estimate of the residuals' own curvature, whichever predicted the last step better.

The loss ``|r|^2 / 2`` has the Hessian ``J^T J + sum_i r_i Hess r_i``; Gauss-Newton keeps the
first term only. Where the residuals stay large at the optimum and curve (a model that cannot
follow the recording, for example), the second term is not small and Gauss-Newton converges
linearly, ever more slowly as the ratio of the two grows. NL2SOL (Dennis, Gay & Welsch 1981,
"An adaptive nonlinear least-squares algorithm", ACM TOMS 7:348-368; RALFit's ``model=3``,
the "hybrid", does the same) keeps a matrix S for that term, updated after every accepted step
by the structured secant (Dennis-Gay-Welsch) update, which makes ``J_new^T J_new + S``
satisfy the secant condition ``(J^T J + S) s = y`` with ``y = g_new - g`` (g = J^T r) while S
alone satisfies ``S s = y# = (J_new - J)^T r_new`` (the change of J seen through the residuals)::

    S+ = S + ((y# - S s) y^T + y (y# - S s)^T) / (y^T s) - (s^T (y# - S s)) y y^T / (y^T s)^2

after S is first sized down by ``min(1, |s^T y#| / |s^T S s|)`` (NL2SOL's sizing, so an S
grown on a large-residual stretch does not dominate once the residuals shrink). The adaptive
choice: both models' predictions of the last step's reduction are compared with the reduction
met, and the next step uses the one that was closer (S starts at 0, so the first steps are
Gauss-Newton's). Where ``J^T J + S`` plus the damping is not positive definite (S need not be)
the step falls back to Gauss-Newton's.

Dense only: S is a matrix of the unknowns' size, which the genes-only (restart-cost) stage
holds anyway; a shooting stage's unknowns include every window's states (:mod:`.box` runs it
on Gauss-Newton's model).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


@jax.jit
def dense_step(system, damping):
    """(J^T J + diag(damping)) d = -g by Cholesky, ``system`` = (J^T J, g, J); NaN where the
    matrix is not positive definite."""
    a, g = system[0], system[1]
    damp = jnp.broadcast_to(damping, a.shape[:1])
    chol = jnp.linalg.cholesky(a + jnp.diag(damp))
    return jax.scipy.linalg.cho_solve((chol, True), -g)


@jax.jit
def dense_curvature(system, d):
    """d^T A d for the system's matrix A."""
    return d @ (system[0] @ d)


@jax.jit
def _predicted(system, step, s_matrix):
    """The reduction of the loss each model predicted for ``step``: Gauss-Newton's, and with
    S (one program rather than a few eager operations)."""
    gauss_newton = system[1] @ step + 0.5 * dense_curvature(system, step)
    return gauss_newton, gauss_newton + 0.5 * (step @ (s_matrix @ step))


@jax.jit
def _update(s_matrix, s, g_old, g_new, j_old, r_new):
    """The Dennis-Gay-Welsch update of S for the step s (NL2SOL's sizing first)."""
    jt_r_new = j_old.T @ r_new
    y = g_new - g_old
    y_sharp = g_new - jt_r_new
    s_s_s = s @ (s_matrix @ s)
    tau = jnp.where(
        jnp.abs(s_s_s) > 0,
        jnp.minimum(1.0, jnp.abs(s @ y_sharp) / jnp.where(s_s_s == 0, 1.0, jnp.abs(s_s_s))),
        1.0,
    )
    sized = tau * s_matrix
    w = y_sharp - sized @ s
    ys = y @ s
    safe = jnp.where(ys > 0, ys, 1.0)
    new = sized + (jnp.outer(w, y) + jnp.outer(y, w)) / safe - (w @ s) * jnp.outer(y, y) / safe**2
    new = 0.5 * (new + new.T)
    # no update where the step did not raise the gradient along itself (no curvature seen)
    return jnp.where((ys > 1e-300) & jnp.all(jnp.isfinite(new)), new, sized)


class Hybrid:
    """NL2SOL's adaptive model for :func:`.box.box_levenberg_marquardt` on a dense system
    ``(J^T J, J^T r, J)``: ``model(system)`` the system to step on, ``update(...)`` after an
    accepted step. ``switches`` counts the changes of model, ``secant_steps`` the steps taken
    on ``J^T J + S``."""

    def __init__(self, size: int):
        self.s_matrix = jnp.zeros((size, size))
        self.use = False
        self.switches = 0
        self.secant_steps = 0

    def model(self, system):
        if not self.use:
            return system
        self.secant_steps += 1
        return (system[0] + self.s_matrix, system[1], system[2])

    def fallback(self):
        """The step on J^T J + S was not defined (not positive definite): Gauss-Newton's."""
        if self.use:
            self.secant_steps -= 1

    def prepare(self, system, r) -> None:
        """Compile :meth:`update`'s programs for these shapes (run once on a zero step, the
        result dropped)."""
        zero = jnp.zeros_like(system[1])
        _predicted(system, zero, self.s_matrix)
        _update(self.s_matrix, zero, system[1], system[1], system[2], r)

    def update(self, old, new, step, r_new, change: float) -> None:
        """After an accepted ``step`` from the linearisation ``old`` to ``new`` (whose
        residuals are ``r_new``) that changed the loss by ``change``: choose the next step's
        model, then update S."""
        gauss_newton, secant = (float(x) for x in _predicted(old, step, self.s_matrix))
        use = abs(change - secant) < abs(change - gauss_newton)
        if np.isfinite(secant) and use != self.use:
            self.switches += 1
            self.use = use
        self.s_matrix = _update(self.s_matrix, step, old[1], new[1], old[2], r_new)
