"""Which cost the refinement uses when it is not told (``fit --cost auto``, ``cost="auto"``).

On a recording (a lab's or another simulator's), marker noise biases the one-step cost's
optimum (dampings several times over on MuJoCo's tendons with 0.5 mm of noise) while
multiple shooting is unbiased at the Cramer-Rao floor (docs/experiments/shooting.md). So ``auto``
refines by shooting, windows of :data:`SHOOTING_HORIZON` frames unless ``--horizon`` says
otherwise, the search still evolving on the one-step cost, where it is affordable: where a
window's unknowns (the genes and its start state: 2 x particles x dimension) are at most
:data:`AFFORDABLE_UNKNOWNS`, each Levenberg-Marquardt step takes well under a second
(benchmarks/README.md, "Multiple shooting": the 4-marker tetrahedron, 42 unknowns, 131 steps
in about 15 s; the 41-marker walk, 660 unknowns, 3-10 s a step). Beyond that, or with
``--refine none``, it refines on the restart cost and says how to ask for shooting.

A file written by ``activebonds simulate`` is a recording too: shooting is exact there as
well, only slower than the one-step cost, which is exact on such data.
"""

from __future__ import annotations

from ..settings import AUTO, FitSettings
from .restart_cost import RESTART
from .shooting_cost import SHOOTING

AFFORDABLE_UNKNOWNS = 300  # genes + a window's start state; more: the restart cost
SHOOTING_HORIZON = 10  # frames per shooting window when --horizon is not given


def choose_cost(
    settings: FitSettings, n_genes: int, n_coordinates: int, horizon_given: bool
) -> tuple[FitSettings, str]:
    """(the settings with ``cost`` chosen, one line saying which and why) for a fit of a
    model with ``n_genes`` genes following ``n_coordinates`` marker coordinates."""

    def chosen(cost: str, horizon: tuple[int, ...]) -> FitSettings:
        values = settings.model_dump(by_alias=True)
        return FitSettings(**{**values, "cost": cost, "horizon": horizon})

    if settings.refine == "none":
        return chosen(RESTART.name, settings.horizon), "cost: restart (auto: --refine none)"
    unknowns = n_genes + 2 * n_coordinates
    if unknowns > AFFORDABLE_UNKNOWNS:
        return chosen(RESTART.name, settings.horizon), (
            f"cost: restart (auto: a shooting window would have {unknowns} unknowns, more than "
            f"{AFFORDABLE_UNKNOWNS}, seconds a step; --cost shooting runs it anyway)"
        )
    horizon = settings.horizon if horizon_given else (SHOOTING_HORIZON,)
    return chosen(SHOOTING.name, horizon), (
        f"cost: shooting (auto: on a recording, marker noise biases the one-step optimum, "
        f"multiple shooting over {horizon[0]}-frame windows is unbiased; --cost restart for "
        "the one-step refinement)"
    )


def choose(
    settings: FitSettings, spec, first, horizon_given: bool
) -> tuple[FitSettings, str | None]:
    """``settings`` with an ``auto`` cost chosen for the model ``spec`` (the bond variant
    fitted) following the first recording ``first`` (its markers and frames as the settings
    select them), and the line saying which and why; ``settings`` as they are (and None) where
    the cost is named."""
    from ..problem import select_recordings

    if settings.cost != AUTO:
        return settings, None
    data = select_recordings(spec, [first], settings)[0]
    coords = data.positions.shape[1] * data.positions.shape[2]
    return choose_cost(settings, spec.layout.n_genes, coords, horizon_given)
