"""The restart cost: the paper's short-term cost (§3.2) at a horizon H, predictions restarted
from the recorded states every H frames (:mod:`.windows`); H = 1 is the one-step cost. Its
variables are the genes alone, so the search can evolve on it and the refinement's stage is
Levenberg-Marquardt over J^T J of the genes."""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ...physics.integrate import stiff
from ..solvers import stage as lm
from .base import ResidualFunction
from .windows import join_windows, make_residuals, make_windows, neighbours_of, rms_mm

NAME = "restart"


class RestartCost:
    """Predictions restarted from the recorded states (:mod:`.base` for the protocol)."""

    name = NAME
    evolvable = True
    refinement_only = False
    needs_states = False

    # ------------------------------------------------------------------ the refinement

    def stage(self, refinement, horizon, genome, max_steps, part: str = "one-step"):
        r = refinement
        windows, residuals = r.restart_residuals(horizon)
        to_genome = r.bounded.to_genome

        def plain(u):
            return residuals(to_genome(u))

        u0 = jnp.asarray(r.bounded.from_genome(genome))
        # the start's and the end's costs by the shared program (the checks against constant
        # velocity reuse it; a start that diverges compiles nothing more)
        start = lm.sum_squares(residuals(to_genome(u0)))
        if not np.isfinite(start) and r.to_newton():  # the start velocities, by Newton
            windows, residuals = r.restart_residuals(horizon)
            start = lm.sum_squares(residuals(to_genome(u0)))
        stopped = None
        if not np.isfinite(start):  # no step can be judged from a non-finite cost
            u, steps, message = u0, 1, "not started"
        else:
            try:
                if r.solver == "dense":  # optimistix compiles the function it is given
                    u, steps, message = lm.solve_dense(plain, u0, max_steps)
                else:
                    # the bounds' transform compiled (an eager transform rounds otherwise,
                    # and near a bound the steps follow the rounding), then the shared
                    # residuals: no second program of the same residuals
                    def residual(u):
                        return residuals(r.to_genome(u))

                    u, steps, message = lm.solve(
                        residual,
                        u0,
                        max_steps,
                        r.bounded.interior,
                        r.jacobian(horizon),
                        r.steps(part, max_steps),
                        r.bounded.box,  # positional: callers' stand-ins take *args
                        r.model,
                    )
            except lm.Interrupted as stop:
                stopped = stop
                u, steps, message = stop.value, stop.steps, lm.interrupted(stop.steps)
        result = np.asarray(to_genome(u), np.float64)
        end = lm.sum_squares(residuals(jnp.asarray(result)))

        def mm(c):
            return float(rms_mm(c, windows.n_terms)) if np.isfinite(c) else float("inf")

        stage = r.judge(horizon, genome, result, (start, end), (mm(start), mm(end)), steps, message)
        stage.cost = self.name
        if stopped is not None:
            raise lm.StageInterrupted(stage) from None
        return stage

    # ------------------------------------------------------------------ the judge

    def residual_function(self, ident, settings, horizon, states) -> ResidualFunction:
        model, data = ident.model, ident.all_data
        log = jnp.asarray(model.layout.log)
        windows = join_windows(
            [
                make_windows(
                    d.positions, d.mask, d.dt, horizon, settings.smooth, neighbours_of(model)
                )
                for d in data
            ]
        )
        residuals = make_residuals(model, windows, settings.substeps, settings.integrator)

        def flat(theta):
            return ravel_pytree(residuals(jnp.where(log, jnp.log(theta), theta)))[0]

        observed = int(np.sum(windows.weight)) * model.dimension
        return ResidualFunction(flat, np.zeros(0), 0, observed, 0)

    def information(self, ident, settings, horizon, states, theta, residuals, max_bytes):
        y = np.concatenate([theta, residuals.extra])
        size = float(residuals.observed) * len(y) * 8  # bytes of the dense Jacobian
        if size > max_bytes:
            raise MemoryError(
                f"the Jacobian would take {size / 2**30:.1f} GiB ({len(y)} variables); "
                f"the limit is {max_bytes / 2**30:.1f} GiB"
            )
        with jax.enable_x64(True):  # scoped, as the least squares
            yj = jnp.asarray(y, jnp.float64)
            resid = np.asarray(jax.jit(residuals.flat)(yj), np.float64)
            jac = np.asarray(jax.jit(jax.jacfwd(residuals.flat))(yj), np.float64)
        keep = np.any(jac != 0, axis=1) | (resid != 0)  # rows of masked-out terms are all 0
        return jac[keep], resid[keep]

    def finer_step(self, ident, settings, genome, horizon, states):
        """One Gauss-Newton step of the restart cost at ``settings.substeps`` (least squares
        over the parameters, columns scaled), its Jacobian at most ``MAX_STEP_BYTES``."""
        layout = ident.model.layout
        if stiff(ident.model.topology):
            # the start velocities of a stiff kind (contacts) are Newton solves with a
            # Jacobian of their own; forward mode over the parameters through them left XLA
            # waiting forever (the tutorial's contact model), as Newton's chord method did
            # on a 41-marker body
            return "a contact's start velocities are Newton solves, not differentiated twice here"
        flat = self.residual_function(ident, settings, horizon, None)
        size = 8.0 * flat.observed * layout.n_genes
        if size > MAX_STEP_BYTES:
            return f"its Jacobian would take {size / 2**20:.0f} MiB"

        def both(theta):  # the residuals beside their Jacobian: one program
            r = flat.flat(theta)
            return r, r

        theta = jnp.asarray(layout.natural(np.asarray(genome, np.float64)), jnp.float64)
        jac, r = (np.asarray(a, np.float64) for a in jax.jit(jax.jacfwd(both, has_aux=True))(theta))
        if not np.all(np.isfinite(r)):
            return NOT_COMPUTED
        if not np.all(np.isfinite(jac)):
            return f"the Jacobian at {settings.substeps} substeps is not finite"
        norms = np.linalg.norm(jac, axis=0)
        norms[norms == 0] = 1.0  # a parameter without effect does not move
        return np.asarray(theta) + np.linalg.lstsq(jac / norms, -r, rcond=None)[0] / norms

    def noise_gain(self, horizon: int) -> float:
        """It predicts frame t + j from x_t and the backward difference x_t - x_t-1, so noise
        n enters as n_t+j - (1 + j) n_t + j n_t-1, of variance (1 + (1 + j)^2 + j^2) sigma^2
        (6 sigma^2 one step ahead), averaged over j = 1..horizon."""
        j = np.arange(1, max(1, int(horizon)) + 1, dtype=np.float64)
        return float(np.sqrt(np.mean(1.0 + (1.0 + j) ** 2 + j**2)))

    # ------------------------------------------------------------------ words

    def describe(self, settings) -> str:
        return "the refinement on the same restart cost (--cost shooting: unbiased by noise)"

    def interval_warning(self, horizon: int, rejected: Sequence[str]) -> str | None:
        if int(horizon) != 1:
            return None
        head = (
            "these intervals come from the one-step cost: on noisy markers they can be up to "
            "18 times too wide and blind to the bias noise puts in the damping (5-7 standard "
            "errors); "
        )
        if not rejected:
            return head + "refit with --cost shooting for intervals that hold"
        tried = f"this fit tried shooting and did not keep it ({'; '.join(rejected)})"
        if any("constant velocity" in r for r in rejected):
            then = (
                ", so refitting with --cost shooting would not help: the model does not "
                "predict the recording over the shooting windows better than constant "
                "velocity; a model that does (see the free run's advice) comes first"
            )
        else:
            then = ", so refitting with --cost shooting alone would not give intervals that hold"
        return head + tried + then

    def stage_note(self, record: dict) -> str:
        return ""

    def rejection(self, record: dict) -> str | None:
        return None  # a restart stage not kept leaves the search's result: nothing tried


MAX_STEP_BYTES = 2**28  # the integrator check's dense Jacobian at most (256 MiB)
NOT_COMPUTED = (
    "the predictions at the check's substeps cannot be computed at these parameters "
    "(a start velocity or a prediction diverged)"
)
RESTART = RestartCost()
