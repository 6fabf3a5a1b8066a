"""What a cost must provide to be fitted, judged and reported (:mod:`activebonds.identify.costs`).

A cost is one object behind this protocol, as a solver is in diffrax (``AbstractSolver``) or
optimistix (``least_squares(fn, solver, y0)``): the refinement, the uncertainty and the
integrator check call it, they never ask which one it is. Its parts:

* the refinement's stage at a horizon (:meth:`Cost.stage`): its windows, residuals and extra
  unknowns, solved through the refinement's shared services
  (:class:`~activebonds.identify.solvers.refine.Refinement`);
* the residuals in natural units with their extra unknowns, for the Gauss-Newton report
  (:meth:`Cost.residual_function`), and the parameters' information there, the extra unknowns
  eliminated (:meth:`Cost.information`);
* one Gauss-Newton step of the same cost at finer substeps (:meth:`Cost.finer_step`);
* its noise factor (:meth:`Cost.noise_gain`) and how it is described in a line
  (:meth:`Cost.describe`), with the caveats of its intervals (:meth:`Cost.interval_warning`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import NamedTuple, Protocol

import numpy as np

# What the consumers pass is named in words, not imported: ``refinement`` a
# :class:`~activebonds.identify.solvers.refine.Refinement`, ``ident`` an
# :class:`~activebonds.identify.problem.Identification`, ``settings`` a
# :class:`~activebonds.identify.settings.FitSettings` (which validate a cost's name here, so
# importing them would make a circle); a stage returns a
# :class:`~activebonds.identify.solvers.stage.Stage`.


class ResidualFunction(NamedTuple):
    """A cost's residuals as one function of flat variables, the parameters first (natural
    units) and the cost's extra unknowns after them (a shooting window's start states)."""

    flat: Callable  # flat variables -> flat residuals (m)
    extra: np.ndarray  # the extra unknowns' values at the optimum (empty: none)
    nuisance: int  # how many extra unknowns
    observed: int  # observed coordinates (residuals that are data)
    links: int  # residuals that are constraints, not data (continuity links)


class Cost(Protocol):
    """A cost a fit's refinement minimises, found by :attr:`name` (``FitSettings.cost``)."""

    name: str
    # whether the search (the ES) can evolve on this cost at the first horizon; where it
    # cannot (its extra unknowns are not genes), it evolves on the exact one-step cost
    evolvable: bool
    # whether this cost exists only as a refinement (``--refine none`` refuses it)
    refinement_only: bool
    # whether its Gauss-Newton report needs the refinement's per-frame states
    needs_states: bool

    def stage(self, refinement, horizon: int, genome: np.ndarray, max_steps: int):
        """One refinement stage from ``genome`` (search space) at ``horizon``."""
        ...

    def residual_function(self, ident, settings, horizon: int, states) -> ResidualFunction: ...

    def information(
        self,
        ident,
        settings,
        horizon: int,
        states,
        theta: np.ndarray,
        residuals: ResidualFunction,
        max_bytes: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(J, r): a matrix whose J^T J is the parameters' information, every extra unknown
        eliminated, and the residuals at the optimum (natural units ``theta``, the extra
        unknowns at ``residuals.extra``); a MemoryError where J would take more than
        ``max_bytes``."""
        ...

    def finer_step(self, ident, settings, genome, horizon: int, states) -> np.ndarray | str:
        """The natural parameters after one Gauss-Newton step of this cost at
        ``settings.substeps`` (the check's finer substeps) from the fit ``genome``; or why
        it cannot be made."""
        ...

    def noise_gain(self, horizon: int) -> float:
        """The residual RMS a correct model leaves on this cost at ``horizon``, per
        coordinate, in units of the markers' white noise sigma."""
        ...

    def describe(self, settings) -> str:
        """The refinement on this cost, in a few words (the fit's costs line)."""
        ...

    def interval_warning(self, horizon: int, rejected: Sequence[str]) -> str | None:
        """Where this cost's intervals cannot be trusted at ``horizon``, in words (``rejected``:
        why costs tried instead were not kept), or None."""
        ...

    def stage_note(self, record: dict) -> str:
        """What a stage's row in the report adds after its outcome ("" for nothing)."""
        ...

    def rejection(self, record: dict) -> str | None:
        """Why a stage of this cost was not kept, one line (``record``: a stage's record), or
        None where it was."""
        ...
