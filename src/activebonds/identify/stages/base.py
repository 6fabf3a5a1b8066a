"""The post-fit stage protocol: what runs after the search, each stage one module.

A stage (the refinement, the baselines, the uncertainty, the validation, and any added with
:func:`~activebonds.identify.stages.register`) declares when it applies, computes a record
from the fit (resumable from the record it saved before), and says what ``fit`` prints, what
the report shows and what a sweep tabulates of that record. The driver runs the registered
stages in order and saves each record through the run directory (RUN/NAME.json); the command
line prints their lines, the report renders their sections and the sweep reads their
columns, none of them computing anything of their own.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from ...data import Trajectory
from ...document import Section
from ..problem import Identification
from ..settings import FitSettings


@dataclass
class Fit:
    """The fit as the stages see it, in order: each may replace ``genome`` (a better model)
    and leave ``products`` for the stages after it."""

    ident: Identification
    settings: FitSettings
    genome: np.ndarray  # the best model's free parameters so far (search space)
    generation: int  # generations the search ran
    status: str  # how the search ended: "completed", "failed: ..."
    run: Any = None  # the run directory (rundir.RunDir), or None for a fit in memory
    held_out: Trajectory | None = None  # the validation frames (settings.validate)
    say: Callable[[str], None] | None = None  # status lines for people
    products: dict[str, Any] = field(default_factory=dict)  # by stage name

    @property
    def completed(self) -> bool:
        return self.status == "completed"

    @property
    def model(self):
        """The model with the current best genome."""
        return self.ident.model.with_genome(self.genome)


@dataclass(frozen=True)
class Outcome:
    """What a stage computed: its record (RUN/NAME.json), and optionally a better genome,
    arrays saved beside the record for a resumed run (RUN/NAME.npz), further files by suffix
    (RUN/NAME.csv; None removes one) and a product for the stages after it."""

    record: dict
    genome: np.ndarray | None = None
    arrays: dict[str, np.ndarray] | None = None
    files: dict[str, str | None] | None = None
    product: Any = None


class PostFitStage(Protocol):
    """One post-fit stage. ``name`` names its record (RUN/NAME.json) and its entry in
    ``FitResult.records``."""

    name: str
    state: str | None  # status.json's status while it runs ("refining"), or None: unchanged

    def doing(self, fit: Fit) -> str:
        """The status line shown while it runs ("estimating the uncertainty ...")."""

    def applies(self, fit: Fit) -> bool:
        """Whether the stage runs after this fit."""

    def run(self, fit: Fit, saved: dict | None, arrays: dict[str, np.ndarray]) -> Outcome:
        """Compute the record; ``saved``/``arrays``: what an earlier, interrupted run of
        this stage saved (None if nothing), to continue from."""

    def lines(self, record: dict) -> list[str]:
        """What ``fit`` prints of the record (plain text, one line each)."""

    def sections(self, record: dict, report: Any) -> list[Section]:
        """What the report shows of the record; ``report`` holds the run's record
        (``report.run``) and the report's predictions (``report.prediction``)."""

    def columns(self, record: dict) -> dict[str, Any]:
        """What a sweep's summary tabulates of the record: column -> value."""
