"""Gradient refinement: Levenberg-Marquardt on the residual vector, in stages.

The steps are solved from the normal equations with optimistix's rules (:mod:`.lm`): for the
restart cost J^T J over the genes, for multiple shooting the blocks of each window with the
window states eliminated (:mod:`.shooting_normal`: memory linear in the frames).
``Refinement(..., solver="dense")`` runs optimistix's own solver on the whole Jacobian
instead (``benchmarks/shooting.py`` compares the two).

After the evolution strategy, ``fit --refine lm`` polishes its best genome with one
Levenberg-Marquardt stage per horizon of ``--horizon`` (a curriculum: each stage starts from
the previous stage's result), on the cost ``--cost`` names:

* ``restart``: the ES's own cost at that horizon (restarts from the recorded states every H
  frames; H = 1 is the paper's one-step cost); the variables are the genes;
* ``shooting``: multiple shooting with windows of H frames (:mod:`.shooting`); the variables
  are the genes and every window's start state (after a warm start of the genes alone on the
  restart cost of that horizon). A shooting stage after another starts its
  states from the previous stage's trajectory.

Bounds are kept through the search space: a gene is ``lo + (hi - lo) (1 + sin u) / 2`` of an
unbounded variable u (the transform of MINUIT), so no step can leave them. A stage whose
result is non-finite, outside the bounds, or costs more than its start is rejected: the
previous result is kept and the stage's record says why in one line.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jax.flatten_util import ravel_pytree

from ..compile_ahead import ahead
from ..costs.restart import (
    constant_velocity_cost,
    join_windows,
    make_residuals,
    make_windows,
    rms_mm,
)
from ..costs.shooting import (
    CONTINUITY_WEIGHT,
    frame_states,
    join_shooting,
    make_shooting,
    shooting_windows,
    start_states,
)
from ..problem import Identification
from ..settings import FitSettings
from .lm import Interrupted, levenberg_marquardt
from .shooting_normal import Normal, damped_step, floored, make_normal, marquardt_diagonal

MAX_STEPS = 500  # Levenberg-Marquardt steps per stage, at most
# ... and of a shooting stage's warm start on the restart cost: a start for the shooting, not
# its answer. On a model that cannot follow the recording its restart cost crawls (the spring
# body on the bundled human walk at H = 10: 0.6 % of its loss in steps 60-100, 2.4 s a step),
# and the shooting refines from wherever it got
WARM_STEPS = 50
# of J^T J's diagonal (Marquardt's scaling): a first step near Gauss-Newton's
INITIAL_DAMPING = 1e-3
RTOL, ATOL = 1e-10, 1e-12  # optimistix's step-size convergence test (search space)
EDGE = 1e-9  # a start on a bound is moved this far (of the span) inside, where sin' != 0


@dataclass
class Stage:
    """One refinement stage, as recorded in RUN/refine.json."""

    horizon: int
    cost: str  # "restart" or "shooting"
    accepted: bool
    message: str  # one line: how it ended
    steps: int
    start_rms_mm: float  # of this stage's position residuals, at its start
    end_rms_mm: float  # ... at its end (the start value if rejected)
    continuity_mm: float | None  # largest continuity defect in position (shooting), at the end
    seconds: float
    genome: list[float] = field(default_factory=list)  # the result (the start if rejected)
    # why shooting was not kept, when this one-step stage was refined in its place, else ""
    instead_of_shooting: str = ""
    warm_steps: int = 0  # of ``steps``, the shooting's warm start's on the restart cost
    # the stage's whole objective (m^2: a shooting stage's continuity defects counted), at its
    # start and end (the start value if rejected); None in records written before
    start_objective: float | None = None
    end_objective: float | None = None

    def record(self) -> dict:
        return asdict(self)


class StageInterrupted(KeyboardInterrupt):
    """Ctrl-C between two steps of a stage: ``stage`` what it had reached (its genome the best
    so far, its message "interrupted after N steps"), for the run to save and resume from."""

    def __init__(self, stage: Stage):
        super().__init__(stage.message)
        self.stage = stage


class Bounded:
    """The search space's box as an unbounded space: g = lo + span (1 + sin u) / 2."""

    def __init__(self, lower, upper):
        self.lower = np.asarray(lower, np.float64)
        self.span = np.asarray(upper, np.float64) - self.lower

    def to_genome(self, u):
        return self.lower + self.span * 0.5 * (1.0 + jnp.sin(u))

    def from_genome(self, genome):
        s = 2.0 * (np.asarray(genome, np.float64) - self.lower) / self.span - 1.0
        return np.arcsin(np.clip(s, -1.0 + EDGE, 1.0 - EDGE))

    def interior(self, u) -> bool:
        """Whether every gene is more than about 0.25 % of its span from its bounds, where
        the transform is flat (|cos u| > 0.1) and a Gauss-Newton step in u means little."""
        return bool(np.all(np.abs(np.cos(np.asarray(u))) > 0.1))

    def inside(self, genome) -> bool:
        g = np.asarray(genome)
        return bool(np.all((g >= self.lower) & (g <= self.lower + self.span)))


def _interrupted(steps: int) -> str:
    return f"interrupted after {steps} steps (Ctrl-C); resume continues from here"


def _sum_squares(tree) -> float:
    return float(_sum_squares_program(tree))


@jax.jit
def _sum_squares_program(tree):  # one program, not three eager ones per leaf
    return sum(jnp.sum(jnp.square(leaf)) for leaf in jax.tree.leaves(tree))


def _solve_dense(residual, y0, max_steps: int):
    """Levenberg-Marquardt from y0 on the dense Jacobian: (y, number of steps, optimistix's
    result message)."""
    solver = optx.LevenbergMarquardt(rtol=RTOL, atol=ATOL)
    sol = optx.least_squares(lambda y, _: residual(y), solver, y0, max_steps=max_steps, throw=False)
    steps = int(sol.stats["num_steps"])
    if sol.result == optx.RESULTS.successful:
        message = "converged"
    elif sol.result == optx.RESULTS.nonlinear_max_steps_reached:
        message = f"stopped at the step limit ({max_steps}) before converging"
    else:
        message = "stopped: " + str(optx.RESULTS[sol.result]).strip().split(".")[0][:100]
    return sol.value, steps, message


@jax.jit
def _dense_diagonal(system):
    """J^T J's diagonal, floored (as :func:`.shooting_normal.marquardt_diagonal`)."""
    return floored(jnp.diagonal(system[0]))


@jax.jit
def _dense_step(system, damping):
    jtj, grad = system
    damp = jnp.broadcast_to(damping, jtj.shape[:1])  # a number or a diagonal
    return jnp.linalg.solve(jtj + jnp.diag(damp), -grad)


def _solve(residual, y0, max_steps: int, interior=None, jacobian=None, on_step=None):
    """Levenberg-Marquardt from y0 (a vector) on its normal equations (J^T J formed once per
    accepted step, each damping a solve of the parameters' size): as :func:`_solve_dense`.
    ``jacobian``: ``y -> J`` (default: forward mode through ``residual``); ``on_step(steps,
    loss)`` after every evaluation."""
    if jacobian is None:
        jacobian = jax.jit(jax.jacfwd(lambda y: ravel_pytree(residual(y))[0]))

    def flat(y):
        return ravel_pytree(residual(y))[0]

    def linearize(y, r):  # r: the residuals at y, already evaluated
        j = jacobian(y)
        grad = j.T @ r
        return (j.T @ j, grad), grad

    return levenberg_marquardt(
        flat,
        linearize,
        _dense_step,
        y0,
        max_steps,
        RTOL,
        ATOL,
        scale=_dense_scale,
        linear_enough=interior,
        diagonal=_dense_diagonal,
        damping=INITIAL_DAMPING,
        on_step=on_step,
    )


@jax.jit
def _dense_scale(system):
    return jnp.max(jnp.diagonal(system[0]))


@jax.jit
def _normal_scale(normal):
    return jnp.maximum(
        jnp.max(jnp.diagonal(normal.diag, axis1=1, axis2=2)), jnp.max(jnp.diagonal(normal.params))
    )


@jax.jit
def _ravel(tree):
    return ravel_pytree(tree)[0]


def _solve_shooting(
    residual, normal, y0, max_steps: int, interior=None, step=damped_step, on_step=None
):
    """Levenberg-Marquardt on a shooting stage's structured normal equations
    (:mod:`.shooting_normal`): as :func:`_solve_dense`, y0 = (u, X [K, P, D], V [K, P, D])."""
    u0, x0, v0 = y0
    k, shape = x0.shape[0], x0.shape

    @jax.jit  # data movement, as one program each rather than eager ops
    def split(z):
        u, states = z
        half = states.shape[1] // 2
        return u, states[:, :half].reshape(shape), states[:, half:].reshape(shape)

    def flat(z):
        return _ravel(residual(split(z)))

    def linearize(z, _):
        system = normal(*z)
        return system, (system.grad_u, system.grad_s)

    z0 = (u0, jnp.concatenate([x0.reshape(k, -1), v0.reshape(k, -1)], axis=1))
    try:
        z, steps, message = levenberg_marquardt(
            flat,
            linearize,
            step,
            z0,
            max_steps,
            RTOL,
            ATOL,
            scale=_normal_scale,
            linear_enough=None if interior is None else (lambda z: interior(z[0])),
            diagonal=marquardt_diagonal,
            damping=INITIAL_DAMPING,
            on_step=on_step,
        )
    except Interrupted as stop:  # the last accepted point, in the caller's form
        raise Interrupted(split(stop.value), stop.steps) from None
    return split(z), steps, message


class Refinement:
    """The stages of one identification's refinement, run one at a time."""

    def __init__(self, ident: Identification, settings: FitSettings, solver: str = "structured"):
        """``solver``: "structured" (normal equations by block, the states of a shooting
        stage eliminated) or "dense" (optimistix on the whole Jacobian, for comparison)."""
        self.ident = ident
        self.settings = settings
        self.solver = solver
        self.bounded = Bounded(ident.problem.lower, ident.problem.upper)
        self.recordings = ident.all_data
        self.states = None  # per recording, per-frame states of the last shooting stage
        self._residuals: dict[int, tuple] = {}  # by horizon: (windows, jitted residuals)
        self._raw: dict[int, object] = {}  # by horizon: the same residuals, not jitted
        self._jacobians: dict[int, object] = {}  # by horizon: the warm start's Jacobian
        # the restart residuals' start velocities by Newton's method, once the fixed point
        # failed at a point that had to be judged (:meth:`_to_newton`)
        self._newton = False
        # the bounds' transform as one program: the restart residuals of u are those of
        # its genome, by the shared program (bit for bit those of both compiled together)
        self._to_genome = jax.jit(self.bounded.to_genome)
        # ``on_step(part, steps, max_steps, objective)`` after each Levenberg-Marquardt
        # evaluation (part: "warm start", "shooting" or "one-step"; objective |r|^2, m^2)
        self.on_step = None

    def _steps(self, part: str, max_steps: int):
        """The solver's ``on_step`` for ``part``, or None."""
        if self.on_step is None:
            return None
        return lambda steps, loss: self.on_step(part, steps, max_steps, 2.0 * loss)

    def stage(self, horizon: int, genome: np.ndarray, max_steps: int | None = None) -> Stage:
        """One stage; ``max_steps`` Levenberg-Marquardt steps at most (default: the
        settings' ``max_steps``, :data:`MAX_STEPS` without one)."""
        if max_steps is None:
            max_steps = getattr(self.settings, "max_steps", MAX_STEPS)
        started = time.time()
        genome = np.asarray(genome, np.float64)
        try:
            if self.settings.cost == "shooting":
                stage = self._shooting(horizon, genome, max_steps)
            else:
                stage = self._restart(horizon, genome, max_steps)
        except StageInterrupted as stop:  # as the stage of this horizon, where it got to
            stop.stage.horizon, stop.stage.cost = int(horizon), self.settings.cost
            stop.stage.seconds = round(time.time() - started, 3)
            raise
        stage.seconds = round(time.time() - started, 3)
        return stage

    def _restart_residuals(self, horizon: int):
        """(windows, jitted ``genome -> residuals``) of the restart cost at ``horizon``,
        built once per refinement: the warm start, the stage and the checks against constant
        velocity share one compiled program."""
        if horizon not in self._residuals:
            s = self.settings
            windows = join_windows(
                [
                    make_windows(d.positions, d.mask, d.dt, horizon, s.smooth)
                    for d in self.recordings
                ]
            )
            residuals = make_residuals(
                self.ident.model, windows, s.substeps, s.integrator, self._newton
            )
            self._raw[horizon] = residuals
            self._residuals[horizon] = (windows, jax.jit(residuals))
        return self._residuals[horizon]

    def _to_newton(self) -> bool:
        """Switch the restart residuals' start velocities from the fixed point to Newton's
        method, their programs rebuilt at their next use; False where that changes nothing
        (already switched, or no start needs a solve). The fixed point is the cheaper program
        (a tetrahedron's stage compiles in half the time) and converges for most models; it
        fails where the damping is strong for the frame interval (the spring body fitted to
        the bundled human walk: every start, at the one-step optimum)."""
        s = self.settings
        if self._newton or (s.substeps == 1 and s.integrator == "euler"):
            return False
        self._newton = True
        self._residuals.clear()
        self._raw.clear()
        self._jacobians.clear()
        return True

    def _restart(self, horizon, genome, max_steps, part: str = "one-step") -> Stage:
        windows, residuals = self._restart_residuals(horizon)
        to_genome = self.bounded.to_genome

        def plain(u):
            return residuals(to_genome(u))

        u0 = jnp.asarray(self.bounded.from_genome(genome))
        # the start's and the end's costs by the shared program (the checks against constant
        # velocity reuse it; a start that diverges compiles nothing more)
        start = _sum_squares(residuals(to_genome(u0)))
        if not np.isfinite(start) and self._to_newton():  # the start velocities, by Newton
            windows, residuals = self._restart_residuals(horizon)
            start = _sum_squares(residuals(to_genome(u0)))
        stopped = None
        if not np.isfinite(start):  # no step can be judged from a non-finite cost
            u, steps, message = u0, 1, "not started"
        else:
            try:
                if self.solver == "dense":  # optimistix compiles the function it is given
                    u, steps, message = _solve_dense(plain, u0, max_steps)
                else:
                    # the bounds' transform compiled (an eager transform rounds otherwise,
                    # and near a bound the steps follow the rounding), then the shared
                    # residuals: no second program of the same residuals
                    def residual(u):
                        return residuals(self._to_genome(u))

                    u, steps, message = _solve(
                        residual,
                        u0,
                        max_steps,
                        self.bounded.interior,
                        self._jacobian(horizon),
                        self._steps(part, max_steps),
                    )
            except Interrupted as stop:
                stopped = stop
                u, steps, message = stop.value, stop.steps, _interrupted(stop.steps)
        result = np.asarray(to_genome(u), np.float64)
        end = _sum_squares(residuals(jnp.asarray(result)))

        def mm(c):
            return float(rms_mm(c, windows.n_terms)) if np.isfinite(c) else float("inf")

        stage = self._judge(
            horizon, genome, result, (start, end), (mm(start), mm(end)), steps, message
        )
        if stopped is not None:
            raise StageInterrupted(stage) from None
        return stage

    def _jacobian(self, horizon: int):
        """The restart residuals' Jacobian at ``horizon`` in the search space (forward mode
        through the residuals themselves, not through their jitted program: the same numbers,
        traced at half the cost), built once per refinement."""
        if horizon not in self._jacobians:
            self._restart_residuals(horizon)
            raw, to_genome = self._raw[horizon], self.bounded.to_genome
            self._jacobians[horizon] = jax.jit(
                jax.jacfwd(lambda y: ravel_pytree(raw(to_genome(y)))[0])
            )
        return self._jacobians[horizon]

    def _shooting(self, horizon, genome, max_steps) -> Stage:
        s = self.settings
        # Warm start: the parameters alone on the restart cost of this horizon (cheap: no
        # state is a variable), so the shooting solve starts near its optimum rather than
        # at the one-step cost's, which marker noise biases (dampings several times over).
        original = genome
        windows = join_shooting(
            [shooting_windows(d.positions, d.mask, d.dt, horizon) for d in self.recordings]
        )
        # the dense path (forward mode over every unknown) keeps its substeps written out
        residuals, trajectory = make_shooting(
            self.ident.model, windows, s.substeps, s.integrator, unroll=self.solver == "dense"
        )
        if self.states is None:
            self.states = [frame_states(d.positions, d.mask, d.dt) for d in self.recordings]
        x0, v0 = start_states(windows, self.states)
        to_genome = self.bounded.to_genome

        def plain(y):
            u, xs, vs = y
            return residuals(to_genome(u), (xs, vs))

        # the shooting's programs compile in the background while the warm start runs
        y0 = (jnp.asarray(self.bounded.from_genome(genome)), jnp.asarray(x0), jnp.asarray(v0))
        residual = ahead(jax.jit(plain), y0)
        if self.solver != "dense":
            normal, step = self._shooting_programs(windows, y0)
        self._check_ahead(1, y0[0])
        trajectory.run = ahead(trajectory.run, y0[0], (y0[1], y0[2]))  # last needed, last
        # interrupted: the stage's start
        warm = self._restart(horizon, genome, min(max_steps, WARM_STEPS), "warm start")
        if warm.accepted:
            genome = np.asarray(warm.genome)
            # the restart cost's optimum at this horizon (its RMS already measured by the
            # warm start): shooting cannot do better there
            unfit = self._versus_constant_velocity(genome, (horizon,), warm.end_rms_mm)
            if unfit:
                return self._one_step_instead(f"not shot: the model's best {unfit[4:]}", original)
            y0 = (jnp.asarray(self.bounded.from_genome(genome)), y0[1], y0[2])
        start_tree = residual(y0)
        stopped = None
        if self.solver == "dense":
            y, steps, message = _solve_dense(plain, y0, max_steps)
        else:
            try:
                y, steps, message = _solve_shooting(
                    residual,
                    normal,
                    y0,
                    max_steps,
                    self.bounded.interior,
                    step,
                    self._steps("shooting", max_steps),
                )
            except Interrupted as stop:
                stopped = stop
                y, steps, message = stop.value, stop.steps, _interrupted(stop.steps)
        end_tree = residual(y)
        result = np.asarray(to_genome(y[0]), np.float64)

        def positions_mm(tree):  # the position residuals only, as an RMS
            return float(rms_mm(float(jnp.sum(jnp.square(tree[0]))), windows.n_terms))

        stage = self._judge(
            horizon,
            original,
            result,
            (_sum_squares(start_tree), _sum_squares(end_tree)),
            (positions_mm(start_tree), positions_mm(end_tree)),
            warm.steps + steps,
            message,
        )
        stage.warm_steps = int(warm.steps)
        if stopped is not None:  # what it reached, its states kept for the resumed stage
            if stage.accepted:
                self.states = trajectory(to_genome(y[0]), (y[1], y[2]))
            raise StageInterrupted(stage) from None
        unfit = stage.accepted and self._versus_constant_velocity(result, (1, horizon))
        if unfit:
            return self._one_step_instead(f"the shot model was rejected: {unfit}", original)
        if stage.accepted:
            gap = float(jnp.max(jnp.abs(end_tree[1]))) if end_tree[1].size else 0.0
            stage.continuity_mm = gap / CONTINUITY_WEIGHT * 1000.0
            self.states = trajectory(to_genome(y[0]), (y[1], y[2]))
        return stage

    def _shooting_programs(self, windows, y0):
        """(normal equations, damped step) of a shooting stage, compiled in the background
        for its unknowns ``y0`` = (u [p], X [K, P, D], V [K, P, D])."""
        s = self.settings
        make = make_normal(
            self.ident.model, windows, s.substeps, s.integrator, self.bounded.to_genome
        )
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

    def _check_ahead(self, horizon: int, u) -> None:
        """The restart residuals at ``horizon`` (the check against constant velocity),
        compiled in the background unless already built."""
        if horizon not in self._residuals:
            windows, residuals = self._restart_residuals(horizon)
            genome = jax.ShapeDtypeStruct(u.shape, u.dtype)
            self._residuals[horizon] = (windows, ahead(residuals, genome))

    def _versus_constant_velocity(self, genome, horizons, known_mm=None) -> str | None:
        """Why ``genome`` loses to the zero-force predictor, or None: its restart predictions
        ``h`` frames ahead (from every recorded state, each h of ``horizons``) against
        constant velocity's on the same terms. Shooting fits free runs of H frames joined
        into one continuous motion; a model that cannot follow the recording over a window
        only trades the markers for continuity there, and ends worse than doing nothing."""
        for h in horizons:
            windows, residuals = self._restart_residuals(h)
            if known_mm is not None:  # ``genome``'s RMS at this single horizon, measured
                model = float(known_mm)
            else:
                cost = _sum_squares(residuals(jnp.asarray(genome)))
                if not np.isfinite(cost) and self._to_newton():  # the starts, by Newton
                    windows, residuals = self._restart_residuals(h)
                    cost = _sum_squares(residuals(jnp.asarray(genome)))
                model = float(rms_mm(cost, windows.n_terms))
            baseline = float(rms_mm(constant_velocity_cost(windows), windows.n_terms))
            if not np.isfinite(model):  # not a loss to constant velocity: no number at all
                return (
                    f"its {h}-frame predictions cannot be computed at these parameters (a "
                    "start velocity or a prediction diverged: more --substeps may hold them)"
                )
            if not model < baseline:
                return (
                    f"its {h}-frame predictions are no better than constant velocity's "
                    f"({model:.4g} vs {baseline:.4g} mm)"
                )
        return None

    def _one_step_instead(self, why: str, genome) -> Stage:
        """The one-step refinement from ``genome``, its message saying ``why`` not shooting."""
        stage = self._restart(1, genome, getattr(self.settings, "max_steps", MAX_STEPS))
        stage.cost = "restart"
        stage.message = f"{why}; refined on the one-step cost instead: {stage.message}"
        stage.instead_of_shooting = why
        return stage

    def _judge(self, horizon, start_genome, result, objective, rms, steps, message):
        """Accept or reject a stage on its own objective (its whole residual vector, so
        continuity defects count for shooting); ``rms``: its position residuals' RMS (mm) at
        the start and the end, for people."""
        start, end = objective
        why = None
        if not np.isfinite(start):
            why = "its start's cost is not finite (a prediction diverged)"
        elif not np.all(np.isfinite(result)) or not np.isfinite(end):
            why = "the refinement diverged (non-finite cost)"
        elif not self.bounded.inside(result):
            why = "the refinement stepped out of the bounds"
        elif end > start * (1 + 1e-12):
            why = f"the refinement made its objective worse ({start:.4g} -> {end:.4g} m^2)"
        accepted = why is None
        return Stage(
            horizon=int(horizon),
            cost=self.settings.cost,
            accepted=accepted,
            message=message if accepted else f"{why}; kept the previous result",
            steps=steps,
            start_rms_mm=rms[0],
            end_rms_mm=rms[1] if accepted else rms[0],
            start_objective=float(start),
            end_objective=float(end) if accepted else float(start),
            continuity_mm=None,
            seconds=0.0,
            genome=[float(g) for g in (result if accepted else start_genome)],
        )
