"""The shooting cost: multiple shooting over windows of H frames (:mod:`.shooting`), whose
start states are unknowns beside the genes. Marker noise does not bias it (no state is taken
from the record); the search cannot evolve on it (the states are not genes), so the search
evolves on the exact one-step cost and the refinement shoots from there, after a warm start
of the genes alone on the restart cost of the same horizon."""

from __future__ import annotations

from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ..compile_ahead import ahead
from ..solvers import stage as lm
from ..solvers.lm import JITTER
from ..solvers.shooting_normal import Normal, damped_step, make_normal, marginal_information
from .base import ResidualFunction
from .restart_cost import NOT_COMPUTED, RESTART
from .shooting import (
    CONTINUITY_WEIGHT,
    frame_states,
    join_shooting,
    make_shooting,
    shooting_windows,
    start_states,
)
from .windows import rms_mm

NAME = "shooting"


def _windows(recordings, horizon: int):
    return join_shooting([shooting_windows(d.positions, d.mask, d.dt, horizon) for d in recordings])


def _stacked(x0, v0):
    """Each window's start state as one row [K, 2 P D]."""
    k = x0.shape[0]
    return jnp.concatenate([jnp.reshape(x0, (k, -1)), jnp.reshape(v0, (k, -1))], axis=1)


class ShootingCost:
    """Multiple shooting (:mod:`.base` for the protocol)."""

    name = NAME
    evolvable = False
    refinement_only = True
    needs_states = True
    # its refinement's bounds (:class:`~activebonds.identify.solvers.refine.Refinement`): the
    # sine transform. On MuJoCo's thrown body's flight (39 frames, the masses free under their
    # total) the active set's shooting stage, on Gauss-Newton's model, stopped at its 100 steps
    # short of the optimum and the masses lost auto's judge; the sine transform's converges
    # there (tests/test_flight_masses.py)
    bounds = "sine"

    # ------------------------------------------------------------------ the refinement

    def stage(self, refinement, horizon, genome, max_steps):
        r, s = refinement, refinement.settings
        # Warm start: the parameters alone on the restart cost of this horizon (cheap: no
        # state is a variable), so the shooting solve starts near its optimum rather than
        # at the one-step cost's, which marker noise biases (dampings several times over).
        original = genome
        windows = _windows(r.recordings, horizon)
        # the dense path (forward mode over every unknown) keeps its substeps written out
        residuals, trajectory = make_shooting(
            r.ident.model, windows, s.substeps, s.integrator, unroll=r.solver == "dense"
        )
        if r.states is None:
            r.states = [frame_states(d.positions, d.mask, d.dt) for d in r.recordings]
        x0, v0 = start_states(windows, r.states)
        to_genome = r.bounded.to_genome

        def plain(y):
            u, xs, vs = y
            return residuals(to_genome(u), (xs, vs))

        # the shooting's programs compile in the background while the warm start runs
        y0 = (jnp.asarray(r.bounded.from_genome(genome)), jnp.asarray(x0), jnp.asarray(v0))
        residual = ahead(jax.jit(plain), y0)
        if r.solver != "dense":
            normal, step = self._programs(r, windows, y0)
        r.check_ahead(1, y0[0])
        trajectory.run = ahead(trajectory.run, y0[0], (y0[1], y0[2]))  # last needed, last
        # interrupted: the stage's start
        warm, y0 = self._warm_start(r, horizon, genome, max_steps, y0)
        if isinstance(warm, str):  # the model's best on the restart cost loses: not shot
            return self._one_step_instead(r, warm, original)
        start_tree = residual(y0)
        stopped = None
        if r.solver == "dense":
            y, steps, message = lm.solve_dense(plain, y0, max_steps)
        else:
            try:
                y, steps, message = lm.solve_shooting(
                    residual,
                    normal,
                    y0,
                    max_steps,
                    r.bounded.interior,
                    step,
                    r.steps("shooting", max_steps),
                    r.bounded.box,
                )
            except lm.Interrupted as stop:
                stopped = stop
                y, steps, message = stop.value, stop.steps, lm.interrupted(stop.steps)
        end_tree = residual(y)
        result = np.asarray(to_genome(y[0]), np.float64)

        def positions_mm(tree):  # the position residuals only, as an RMS
            return float(rms_mm(float(jnp.sum(jnp.square(tree[0]))), windows.n_terms))

        stage = r.judge(
            horizon,
            original,
            result,
            (lm.sum_squares(start_tree), lm.sum_squares(end_tree)),
            (positions_mm(start_tree), positions_mm(end_tree)),
            warm.steps + steps,
            message,
        )
        stage.cost = self.name
        stage.warm_steps = int(warm.steps)
        if stopped is not None:  # what it reached, its states kept for the resumed stage
            if stage.accepted:
                r.states = trajectory(to_genome(y[0]), (y[1], y[2]))
            raise lm.StageInterrupted(stage) from None
        unfit = stage.accepted and r.versus_constant_velocity(result, (1, horizon))
        if unfit:
            return self._one_step_instead(r, f"the shot model was rejected: {unfit}", original)
        if stage.accepted:
            gap = float(jnp.max(jnp.abs(end_tree[1]))) if end_tree[1].size else 0.0
            stage.continuity_mm = gap / CONTINUITY_WEIGHT * 1000.0
            r.states = trajectory(to_genome(y[0]), (y[1], y[2]))
        return stage

    def _warm_start(self, r, horizon, genome, max_steps, y0):
        """(the warm start's stage, the unknowns from its genes), or (why not to shoot, y0):
        its result, the restart cost's optimum at this horizon (its RMS already measured),
        loses to constant velocity there, and shooting cannot do better."""
        warm = RESTART.stage(r, horizon, genome, min(max_steps, lm.WARM_STEPS), "warm start")
        if not warm.accepted:
            return warm, y0
        genome = np.asarray(warm.genome)
        unfit = r.versus_constant_velocity(genome, (horizon,), warm.end_rms_mm)
        if unfit:
            return f"not shot: the model's best {unfit[4:]}", y0
        return warm, (jnp.asarray(r.bounded.from_genome(genome)), y0[1], y0[2])

    def _programs(self, r, windows, y0):
        """(normal equations, damped step) of a shooting stage, compiled in the background
        for its unknowns ``y0`` = (u [p], X [K, P, D], V [K, P, D])."""
        s = r.settings
        make = make_normal(r.ident.model, windows, s.substeps, s.integrator, r.bounded.to_genome)
        u, x = y0[0], y0[1]
        k, p, n = x.shape[0], u.shape[0], 2 * int(np.prod(x.shape[1:]))
        f = u.dtype

        def shape(*dims):
            return jax.ShapeDtypeStruct(dims, f)

        normal = ahead(jax.jit(make), shape(p), shape(k, n))
        system = Normal(
            shape(k, n, n), shape(k - 1, n, n), shape(k, n, p), shape(p, p), shape(k, n), shape(p)
        )
        return normal, ahead(damped_step, system, (shape(p), shape(k, n)))

    def _one_step_instead(self, r, why: str, genome):
        """The one-step refinement from ``genome``, its message saying ``why`` not shooting."""
        stage = RESTART.stage(r, 1, genome, r.max_steps())
        stage.cost = RESTART.name
        stage.message = f"{why}; refined on the one-step cost instead: {stage.message}"
        stage.instead_of_shooting = why
        return stage

    # ------------------------------------------------------------------ the judge

    def residual_function(self, ident, settings, horizon, states) -> ResidualFunction:
        model = ident.model
        layout = model.layout
        log = jnp.asarray(layout.log)
        windows = _windows(ident.all_data, horizon)
        residuals, _ = make_shooting(model, windows, settings.substeps, settings.integrator)
        x0, v0 = start_states(windows, states)
        observed = int(np.sum(windows.weight)) * model.dimension
        p = layout.n_genes

        def flat(y):
            theta, xs, vs = y[:p], y[p : p + x0.size], y[p + x0.size :]
            genome = jnp.where(log, jnp.log(theta), theta)
            tree = residuals(genome, (xs.reshape(x0.shape), vs.reshape(v0.shape)))
            return ravel_pytree(tree)[0]

        extra = np.concatenate([np.ravel(x0), np.ravel(v0)])
        links = int(np.sum(windows.link)) * 2 * model.dimension * len(model.particle_names)
        return ResidualFunction(flat, extra, x0.size + v0.size, observed, links)

    def information(self, ident, settings, horizon, states, theta, residuals, max_bytes):
        """R [p, p] with R^T R the parameters' information with every window state
        eliminated (:func:`~activebonds.identify.solvers.shooting_normal.marginal_information`,
        built window by window: no dense Jacobian); R stands for the Jacobian: its covariance
        ``s^2 (R^T R)^-1`` is the parameters' block of the full one's."""
        model = ident.model
        log = jnp.asarray(model.layout.log)
        windows = _windows(ident.all_data, horizon)
        x0, v0 = start_states(windows, states)
        y = np.concatenate([theta, residuals.extra])
        with jax.enable_x64(True):
            normal = make_normal(
                model,
                windows,
                settings.substeps,
                settings.integrator,
                lambda t: jnp.where(log, jnp.log(t), t),
            )
            system = jax.jit(normal)(jnp.asarray(theta), _stacked(x0, v0))
            info = np.asarray(marginal_information(system))
            resid = np.asarray(jax.jit(residuals.flat)(jnp.asarray(y, jnp.float64)), np.float64)
        if not np.all(np.isfinite(info)):
            return np.full(info.shape, np.nan), resid
        w, v = np.linalg.eigh(info)
        return np.sqrt(np.maximum(w, 0.0))[:, None] * v.T, resid

    def finer_step(self, ident, settings, genome, horizon, states):
        """One Gauss-Newton step of multiple shooting at ``settings.substeps`` from the fit's
        parameters and window states (the normal equations by window, the states
        eliminated: :mod:`~activebonds.identify.solvers.shooting_normal`)."""
        if states is None:
            return "the shooting fit's states are not at hand"
        windows = _windows(ident.all_data, horizon)
        bounded = lm.Bounded(ident.problem.lower, ident.problem.upper)
        make = make_normal(
            ident.model, windows, settings.substeps, settings.integrator, bounded.to_genome
        )
        x0, v0 = start_states(windows, states)
        u = jnp.asarray(bounded.from_genome(np.asarray(genome, np.float64)))
        system = jax.jit(make)(u, _stacked(x0, v0))
        scale = float(jnp.max(jnp.abs(jnp.diagonal(system.diag, axis1=1, axis2=2))))
        du, _ = damped_step(system, JITTER * max(scale, float(jnp.max(jnp.diag(system.params)))))
        after = np.asarray(bounded.to_genome(u + du), np.float64)
        if not np.all(np.isfinite(after)):
            return NOT_COMPUTED
        return np.asarray(ident.model.layout.natural(after), np.float64)

    def noise_gain(self, horizon: int) -> float:
        """Output error, the states free: a correct model leaves the noise itself."""
        return 1.0

    # ------------------------------------------------------------------ words

    def describe(self, settings) -> str:
        return (
            f"the refinement on multiple shooting ({settings.substeps} {settings.integrator} "
            "substep(s)), which marker noise does not bias"
        )

    def interval_warning(self, horizon: int, rejected: Sequence[str]) -> str | None:
        return None

    def stage_note(self, record: dict) -> str:
        """Where a stage's position RMS rose while its objective fell (its windows gave up
        fitting the markers to join): both, said."""
        a, b = record.get("start_objective"), record.get("end_objective")
        if a is None or b is None or not record["end_rms_mm"] > record["start_rms_mm"]:
            return ""
        return (
            f" (the markers' RMS rose as the windows were made to join: the objective, markers "
            f"and joins together, fell from {a:.4g} to {b:.4g} m^2)"
        )

    def rejection(self, record: dict) -> str | None:
        if record.get("accepted"):
            return None
        return f"horizon {record['horizon']}: {record['message']}"


SHOOTING = ShootingCost()
