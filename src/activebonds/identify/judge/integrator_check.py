"""Are a fit's integrator steps fine enough? Ask the data at four times as many.

A fit with one integrator step per frame (``--substeps 1``) of a motion that is finer than the
frames can sit several standard errors off with no visible symptom (64 % coverage of the 95 %
intervals measured on the triangle, docs/experiments/uncertainty.md): the integrator's own error is
absorbed by the parameters. So can a fit at the 4 Euler substeps that advice names, on
MuJoCo's tendons at 100 Hz (a new user's run: 95 % intervals that missed the truth, no
warning). The check moves the fit to the same cost at :data:`FACTOR` times its substeps
(:func:`finer`) by one Gauss-Newton step from its optimum, ``d = -J^+ r`` with r and J the
residuals and their Jacobian there (to first order the optimum there), and holds
every determined parameter's move against its standard error (a parameter on a bound is
not judged): a move beyond the 95 %
interval's half-width (1.96 standard errors) means the intervals do not describe the
integrator's error, and the fit says so with the numbers.

For the restart cost (the one-step cost and its horizons: a dense Jacobian of at most
:data:`~activebonds.identify.costs.restart_cost.MAX_STEP_BYTES`) and for multiple shooting (the step from the normal equations by window, the
window states eliminated, from the fit's states), and for at most ``MAX_GENES`` parameters;
otherwise the check is not made and the warning stays in words.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import jax
import numpy as np

from .. import costs
from ..problem import Identification
from ..settings import FitSettings
from .uncertainty import Z95

FACTOR = 4  # the check's substeps: this many times the fit's
CHECKED_EULER = 4  # first-order substeps checked up to (second order: one substep alone)


def applies(settings: FitSettings) -> bool:
    """Whether a fit with ``settings`` is checked: one substep per frame (any integrator), or
    Euler (first order) at up to :data:`CHECKED_EULER` substeps."""
    s = int(settings.substeps)
    return s == 1 or (settings.stepper.scheme.order == 1 and s <= CHECKED_EULER)


def finer(settings: FitSettings) -> int:
    """The check's substeps: :data:`FACTOR` times the fit's."""
    return FACTOR * int(settings.substeps)


MAX_GENES = 200  # a larger model is not checked (the check would compile longer than it fits)
AT_BOUND = 1e-6  # of its span: a parameter this close to a bound is held there, not judged


@dataclass(frozen=True)
class SubstepsCheck:
    """How far the parameters move at :func:`finer` substeps, in their standard errors."""

    substeps: int
    largest_sd: float  # the largest |move| / standard error over the determined parameters
    parameter: str  # ... of this parameter (as people read it)
    name: str  # ... its key in the model's layout
    before: float  # its value at the fit's substeps
    after: float  # ... and at the check's substeps (first order)
    moved: int  # determined parameters that move by more than 1.96 standard errors
    determined: int
    fitted: int = 1  # the fit's substeps

    def record(self) -> dict:
        return asdict(self)

    @property
    def steps(self) -> str:
        """The fit's substeps in words: 'one step', '2 steps'."""
        return "one step" if self.fitted == 1 else f"{self.fitted} steps"

    def warning(self) -> str | None:
        """One sentence where the intervals do not hold at the fit's substeps, else None."""
        if not self.moved:
            return None
        steps = self.steps
        return (
            f"at --substeps {self.substeps} the parameters move: {self.moved} of "
            f"{self.determined} by more than their 95 % interval, the most {self.parameter} "
            f"({self.before:.6g} -> {self.after:.6g}, {self.largest_sd:.1f} standard errors); "
            f"{steps} per frame {'is' if self.fitted == 1 else 'are'} too coarse for this "
            f"motion and these intervals do not describe it: refit with --substeps "
            f"{self.substeps}"
        )


EXACT_MM = 1e-6  # residuals below this (mm a coordinate): the fit is exact, to rounding


def exact_warning(checked: SubstepsCheck, sigma_mm: float) -> str:
    """:meth:`SubstepsCheck.warning` for a fit whose residuals are rounding (``sigma_mm``
    below :data:`EXACT_MM`): a recording made by this very integration (a file of
    ``activebonds simulate``), which the parameters describe exactly. The parameters' move at
    finer substeps is real, but there a finer integration is another model of the same
    frames, and no refit is called for."""
    return (
        f"the fit is exact at {checked.steps} per frame (residuals {sigma_mm:.2g} mm, rounding): the "
        f"recording was likely made by this very integration; at --substeps "
        f"{checked.substeps} the parameters would move ({checked.moved} of {checked.determined} "
        f"by more than their 95 % interval, the most {checked.parameter}: "
        f"{checked.before:.6g} -> {checked.after:.6g}), a finer integration being another "
        "model of these frames; refit at finer substeps only for a recording of a real motion"
    )


def check(
    ident: Identification,
    settings: FitSettings,
    genome,
    horizon: int,
    estimates,
    cost: str = costs.DEFAULT,
    states=None,
) -> SubstepsCheck | str:
    """The check of a fit ``genome`` (search space) on ``cost`` (a cost's name; one that
    needs them with the refinement's per-frame ``states``) at ``horizon``, its ``estimates``
    (:class:`.uncertainty.Estimate`, natural units); or why it was not made."""
    if ident.model.layout.n_genes > MAX_GENES:
        return f"more than {MAX_GENES} parameters (its compilation would outlast the fit's)"
    more = settings.model_copy(update={"substeps": finer(settings)})
    with jax.enable_x64(True):
        after = costs.get(cost).finer_step(ident, more, genome, horizon, states)
    if isinstance(after, str):
        return after
    g, lo, hi = np.asarray(genome, np.float64), ident.problem.lower, ident.problem.upper
    inside = np.minimum(g - lo, hi - g) > AT_BOUND * (hi - lo)  # a bound holds the others
    rows = [
        (abs(a - e.value) / e.std_error, e, a)
        for e, a, free in zip(estimates, after, inside, strict=True)
        if e.determined and e.std_error and free
    ]
    if not rows:
        return "no parameter is determined"
    sd, worst, value = max(rows, key=lambda row: row[0])
    return SubstepsCheck(
        substeps=finer(settings),
        largest_sd=float(sd),
        parameter=worst.label or worst.name,
        name=worst.name,
        before=float(worst.value),
        after=float(value),
        moved=int(sum(bool(row[0] > Z95) for row in rows)),
        determined=len(rows),
        fitted=int(settings.substeps),
    )
