"""What a candidate model of ``activebonds auto``'s fit step is: something that, given the
workspace and the model kept so far, proposes a model file and how to fit it (or nothing),
and what a fitted candidate is once judged."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from ...identify.settings import FitSettings
    from ..judge import Judged
    from ..workspace import Workspace

# where marker noise dominates the one-step scores (:class:`~.data.smoothing.Noise`), the kept
# model is refined by multiple shooting, whose optimum noise does not bias, up to this many
# parameters (the stage of the 5-mass, 24-parameter MuJoCo recording: 5-16 s); the flight's
# masses are identified by it up to as many
MAX_SHOT = 100
SHOOTING = {
    "cost": "shooting",
    "horizon": (10,),
    "integrator": "verlet",
    "substeps": 5,
    # a model that explains the motion converges in tens of steps (MuJoCo's tendons: 20-48);
    # one that does not crawls, and a crawl's end is no better an answer
    "max_steps": 100,
}


@dataclass(frozen=True)
class Proposal:
    """A candidate's model, ready to fit."""

    run: str  # the run folder's name under OUT, e.g. "run-ground"
    model: Path  # a model file the candidate wrote in OUT
    settings: FitSettings  # how it is fitted (frames = the fitted frames)
    what: str  # one line said before its fit
    insist: bool = False  # kept whatever the judge says (--up/--gravity insisting on gravity)


@dataclass(frozen=True)
class Tried:
    """A fitted candidate: its name, its run folder, the judge's scores, its one-step RMS on
    the fitted frames (the fit's own, mm)."""

    name: str
    run: Path
    judged: Judged
    fitted_mm: float = float("nan")


class Candidate(Protocol):
    """A candidate model of the fit step, registered in :data:`~.candidates.CANDIDATES`.
    ``propose`` may fit what it needs to make its model (the flight's masses are fitted on
    the flight first), writes the model file in ``ws.folder`` and returns how to fit it, or
    None where it does not apply (it may say why through ``ws.say``). ``kept``: the
    candidate kept so far (None before the first)."""

    name: str

    def propose(self, ws: Workspace, kept: Tried | None) -> Proposal | None: ...
