"""The ground candidate: the structure with the scaffold's gravity and ground contacts
(``OUT/ground.toml``, written by the structure step where the scaffold has either), fitted
from its exact optimum with the contacts held, on the one-step cost (``OUT/run-ground``).
``--up`` or ``--gravity`` insists on it."""

from __future__ import annotations

from .base import Proposal


class GroundCandidate:
    """Gravity and ground contacts, where the structure step wrote them."""

    name = "ground"

    def propose(self, ws, kept) -> Proposal | None:
        if not ws.folder.ground.exists():
            return None
        insist = ws.options.gravity is True or ws.options.up is not None
        return Proposal(
            run="run-ground",
            model=ws.folder.ground,
            settings=ws.one_step(),
            what=(
                f"the model with gravity and ground contacts ({ws.folder.ground.name}), from "
                "its exact optimum with the contacts held, cost one step"
                + ("; --up or --gravity insists on gravity: kept whatever it scores" * insist)
            ),
            insist=insist,
        )
