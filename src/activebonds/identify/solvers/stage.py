"""What every refinement stage shares, whatever its cost: the stage's record, the bounds as an
unbounded search space (the transform of MINUIT), and Levenberg-Marquardt on dense or
structured normal equations (:mod:`.lm`, :mod:`.shooting_normal`). A cost's own stage
(:mod:`activebonds.identify.costs`) composes these; :mod:`.refine` runs the stages."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from .box import box_levenberg_marquardt
from .hybrid import Hybrid, dense_curvature, dense_step
from .lm import Interrupted, levenberg_marquardt
from .shooting_normal import curvature, damped_step, floored, marquardt_diagonal

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
# how the bounds are kept: "active" (:mod:`.box`: the genes themselves, an active set, steps
# projected onto the box) or "sine" (:class:`Bounded`: the transform, the solver unbounded)
BOUNDS = "active"
# the model of the genes-only stage's loss: "hybrid" (NL2SOL's, :mod:`.hybrid`) or
# "gauss-newton"; the shooting stage's is Gauss-Newton's (its unknowns include the states)
MODEL = "hybrid"


@dataclass
class Stage:
    """One refinement stage, as recorded in RUN/refine.json."""

    horizon: int
    cost: str  # the name of its cost (:mod:`activebonds.identify.costs`)
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
    """The search space's box as an unbounded space: g = lo + span (1 + sin u) / 2 (``box``
    None: the solver sees no bounds; :class:`.box.Box` for the active set)."""

    box = None

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


def interrupted(steps: int) -> str:
    return f"interrupted after {steps} steps (Ctrl-C); resume continues from here"


def sum_squares(tree) -> float:
    return float(_sum_squares_program(tree))


@jax.jit
def _sum_squares_program(tree):  # one program, not three eager ones per leaf
    return sum(jnp.sum(jnp.square(leaf)) for leaf in jax.tree.leaves(tree))


def solve_dense(residual, y0, max_steps: int):
    """Levenberg-Marquardt from y0 on the dense Jacobian: (y, number of steps, optimistix's
    result message)."""
    import optimistix as optx  # here: its import costs a third of a second

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


def solve(
    residual,
    y0,
    max_steps: int,
    interior=None,
    jacobian=None,
    on_step=None,
    box=None,
    model: str = MODEL,
):
    """Levenberg-Marquardt from y0 (a vector) on its normal equations (J^T J formed once per
    accepted step, each damping a solve of the parameters' size): as :func:`solve_dense`.
    ``jacobian``: ``y -> J`` (default: forward mode through ``residual``); ``on_step(steps,
    loss)`` after every evaluation. ``box``: (lower, upper) of y, kept by :mod:`.box`'s active
    set (y the genes themselves), on ``model``'s model of the loss ("hybrid":
    :mod:`.hybrid`, or "gauss-newton"); None: y unbounded (the sine transform's u)."""
    if jacobian is None:
        jacobian = jax.jit(jax.jacfwd(lambda y: ravel_pytree(residual(y))[0]))

    def flat(y):
        return ravel_pytree(residual(y))[0]

    if box is not None:

        def linearize_box(y, r):
            j = jacobian(y)
            jtj, grad = _normal(j, r)
            return (jtj, grad, j), grad

        return box_levenberg_marquardt(
            flat,
            linearize_box,
            dense_step,
            dense_curvature,
            y0,
            box[0],
            box[1],
            max_steps,
            RTOL,
            ATOL,
            scale=_dense_scale,
            diagonal=_dense_diagonal,
            damping=INITIAL_DAMPING,
            on_step=on_step,
            secant=Hybrid(int(np.size(y0))) if model == "hybrid" else None,
        )

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
def _normal(j, r):
    return j.T @ j, j.T @ r


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


def solve_shooting(
    residual,
    normal,
    y0,
    max_steps: int,
    interior=None,
    step=damped_step,
    on_step=None,
    box=None,
):
    """Levenberg-Marquardt on a shooting stage's structured normal equations
    (:mod:`.shooting_normal`): as :func:`solve_dense`, y0 = (u, X [K, P, D], V [K, P, D]).
    ``box``: (lower, upper) of u, kept by :mod:`.box`'s active set (the states unbounded)."""
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
        if box is not None:
            free = jnp.full(z0[1].shape, jnp.inf)
            z, steps, message = box_levenberg_marquardt(
                flat,
                linearize,
                step,
                curvature,
                z0,
                (jnp.asarray(box[0]), -free),
                (jnp.asarray(box[1]), free),
                max_steps,
                RTOL,
                ATOL,
                scale=_normal_scale,
                diagonal=marquardt_diagonal,
                damping=INITIAL_DAMPING,
                on_step=on_step,
            )
            return split(z), steps, message
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
