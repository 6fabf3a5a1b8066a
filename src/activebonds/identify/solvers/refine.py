"""Gradient refinement: Levenberg-Marquardt on the residual vector, in stages.

The steps are solved from the normal equations with optimistix's rules (:mod:`.lm`): for the
restart cost J^T J over the genes, for multiple shooting the blocks of each window with the
window states eliminated (:mod:`.shooting_normal`: memory linear in the frames).
``Refinement(..., solver="dense")`` runs optimistix's own solver on the whole Jacobian
instead (``benchmarks/shooting.py`` compares the two).

After the evolution strategy, ``fit --refine lm`` polishes its best genome with one
Levenberg-Marquardt stage per horizon of ``--horizon`` (a curriculum: each stage starts from
the previous stage's result), on the cost ``--cost`` names; the stage is the cost's own
(:mod:`activebonds.identify.costs`), run through this module's shared services:

* the restart cost (:mod:`activebonds.identify.costs.restart_cost`): the ES's own cost at that
  horizon (restarts from the recorded states every H frames; H = 1 is the paper's one-step
  cost); the variables are the genes;
* multiple shooting (:mod:`activebonds.identify.costs.shooting_cost`): windows of H frames;
  the variables are the genes and every window's start state (after a warm start of the genes
  alone on the restart cost of that horizon). A shooting stage after another starts its
  states from the previous stage's trajectory.

Bounds are kept by an active set (:mod:`.box`, the default ``bounds="active"``; a cost may
name its own, the shooting cost keeps the sine transform): the genes
are the unknowns, a gene on its bound whose gradient points out is held, the steps are
projected onto the box; the genes-only stage's model of the loss is NL2SOL's adaptive one
(:mod:`.hybrid`). ``bounds="sine"`` keeps the earlier way, through the search space: a gene
is ``lo + (hi - lo) (1 + sin u) / 2`` of an unbounded variable u (the transform of MINUIT),
so no step can leave them (``benchmarks/solver.py`` compares the two). A stage whose
result is non-finite, outside the bounds, or costs more than its start is rejected: the
previous result is kept and the stage's record says why in one line.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from ...physics.integrators import Integrator
from .. import costs
from ..compile_ahead import ahead
from ..costs.windows import (
    constant_velocity_cost,
    join_windows,
    make_residuals,
    make_windows,
    rms_mm,
)
from ..problem import Identification
from ..settings import FitSettings
from .box import Box
from .stage import (  # noqa: F401 (the stage's parts, where callers have found them)
    BOUNDS,
    EDGE,
    INITIAL_DAMPING,
    MAX_STEPS,
    MODEL,
    WARM_STEPS,
    Bounded,
    Stage,
    StageInterrupted,
    solve,
    solve_dense,
    solve_shooting,
    sum_squares,
)


class Refinement:
    """The stages of one identification's refinement, run one at a time, each on the cost its
    settings name (:mod:`activebonds.identify.costs`): the refinement calls the cost's stage,
    it never asks which cost it is. It holds what every cost's stage shares: the bounds as an
    unbounded space, the restart residuals at each horizon (the warm start of a shooting
    stage and the checks against constant velocity use them too), the per-frame states of
    the last stage that had them."""

    def __init__(
        self,
        ident: Identification,
        settings: FitSettings,
        solver: str = "structured",
        bounds: str | None = None,
        model: str | None = None,
    ):
        """``solver``: "structured" (normal equations by block, the states of a shooting
        stage eliminated) or "dense" (optimistix on the whole Jacobian, for comparison);
        ``bounds``: "active" (:mod:`.box`) or "sine" (:class:`.stage.Bounded`; always with
        "dense", which has no bounds of its own), default :data:`.stage.BOUNDS`; ``model``:
        the genes-only stage's model with the active set, "hybrid" or "gauss-newton"
        (default :data:`.stage.MODEL`)."""
        self.ident = ident
        self.settings = settings
        self.cost = costs.get(settings.cost)
        self.solver = solver
        if bounds is None:  # the cost's own where it has one (the shooting cost's: "sine")
            bounds = getattr(self.cost, "bounds", BOUNDS)
        if bounds not in ("active", "sine"):
            raise ValueError(f"bounds must be 'active' or 'sine', got {bounds!r}")
        self.model = MODEL if model is None else model
        kind = Box if bounds == "active" and solver != "dense" else Bounded
        self.bounded = kind(ident.problem.lower, ident.problem.upper)
        self.recordings = ident.all_data
        self.states = None  # per recording, per-frame states of the last shooting stage
        self._residuals: dict[int, tuple] = {}  # by horizon: (windows, jitted residuals)
        self._raw: dict[int, object] = {}  # by horizon: the same residuals, not jitted
        self._jacobians: dict[int, object] = {}  # by horizon: the warm start's Jacobian
        # the restart residuals' start velocities by Newton's method, once the fixed point
        # failed at a point that had to be judged (:meth:`to_newton`)
        self._newton = False
        # the bounds' transform as one program: the restart residuals of u are those of
        # its genome, by the shared program (bit for bit those of both compiled together)
        self.to_genome = jax.jit(self.bounded.to_genome)
        # ``on_step(part, steps, max_steps, objective)`` after each Levenberg-Marquardt
        # evaluation (part: "warm start", "shooting" or "one-step"; objective |r|^2, m^2)
        self.on_step = None

    @property
    def integrator(self) -> Integrator:
        return Integrator(self.settings.integrator, self.settings.substeps)

    def steps(self, part: str, max_steps: int):
        """The solver's ``on_step`` for ``part``, or None."""
        if self.on_step is None:
            return None
        return lambda steps, loss: self.on_step(part, steps, max_steps, 2.0 * loss)

    def max_steps(self) -> int:
        """The settings' ``max_steps`` (:data:`MAX_STEPS` without one)."""
        return getattr(self.settings, "max_steps", MAX_STEPS)

    def stage(self, horizon: int, genome: np.ndarray, max_steps: int | None = None) -> Stage:
        """One stage on the settings' cost; ``max_steps`` Levenberg-Marquardt steps at most
        (default: :meth:`max_steps`)."""
        if max_steps is None:
            max_steps = self.max_steps()
        started = time.time()
        genome = np.asarray(genome, np.float64)
        try:
            stage = self.cost.stage(self, horizon, genome, max_steps)
        except StageInterrupted as stop:  # as the stage of this horizon, where it got to
            stop.stage.horizon, stop.stage.cost = int(horizon), self.cost.name
            stop.stage.seconds = round(time.time() - started, 3)
            raise
        stage.seconds = round(time.time() - started, 3)
        return stage

    def restart_residuals(self, horizon: int):
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

    def to_newton(self) -> bool:
        """Switch the restart residuals' start velocities from the fixed point to Newton's
        method, their programs rebuilt at their next use; False where that changes nothing
        (already switched, or no start needs a solve). The fixed point is the cheaper program
        (a tetrahedron's stage compiles in half the time) and converges for most models; it
        fails where the damping is strong for the frame interval (the spring body fitted to
        the bundled human walk: every start, at the one-step optimum)."""
        if self._newton or self.integrator.exact_backward:
            return False
        self._newton = True
        self._residuals.clear()
        self._raw.clear()
        self._jacobians.clear()
        return True

    def jacobian(self, horizon: int):
        """The restart residuals' Jacobian at ``horizon`` in the search space (forward mode
        through the residuals themselves, not through their jitted program: the same numbers,
        traced at half the cost), built once per refinement."""
        if horizon not in self._jacobians:
            self.restart_residuals(horizon)
            raw, to_genome = self._raw[horizon], self.bounded.to_genome
            self._jacobians[horizon] = jax.jit(
                jax.jacfwd(lambda y: ravel_pytree(raw(to_genome(y)))[0])
            )
        return self._jacobians[horizon]

    def check_ahead(self, horizon: int, u) -> None:
        """The restart residuals at ``horizon`` (the check against constant velocity),
        compiled in the background unless already built."""
        if horizon not in self._residuals:
            windows, residuals = self.restart_residuals(horizon)
            genome = jax.ShapeDtypeStruct(u.shape, u.dtype)
            self._residuals[horizon] = (windows, ahead(residuals, genome))

    def versus_constant_velocity(self, genome, horizons, known_mm=None) -> str | None:
        """Why ``genome`` loses to the zero-force predictor, or None: its restart predictions
        ``h`` frames ahead (from every recorded state, each h of ``horizons``) against
        constant velocity's on the same terms. A cost that fits free runs of H frames joined
        into one continuous motion (shooting) can, on a model that cannot follow the
        recording over a window, only trade the markers for continuity there, and end worse
        than doing nothing."""
        for h in horizons:
            windows, residuals = self.restart_residuals(h)
            if known_mm is not None:  # ``genome``'s RMS at this single horizon, measured
                model = float(known_mm)
            else:
                cost = sum_squares(residuals(jnp.asarray(genome)))
                if not np.isfinite(cost) and self.to_newton():  # the starts, by Newton
                    windows, residuals = self.restart_residuals(h)
                    cost = sum_squares(residuals(jnp.asarray(genome)))
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

    def judge(self, horizon, start_genome, result, objective, rms, steps, message) -> Stage:
        """Accept or reject a stage on its own objective (its whole residual vector, so a
        shooting stage's continuity defects count); ``rms``: its position residuals' RMS (mm)
        at the start and the end, for people."""
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
            cost=self.cost.name,
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
