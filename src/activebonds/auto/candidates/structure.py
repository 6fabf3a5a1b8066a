"""The first candidate: the structure step's model (``OUT/structure.toml``) fitted from its
exact optimum on the one-step cost, whose optimum it is (``OUT/run``); always kept first."""

from __future__ import annotations

from .base import Proposal


class StructureCandidate:
    """The decided structure, the ES seeded at its exact optimum."""

    name = "structure"

    def propose(self, ws, kept) -> Proposal:
        return Proposal(
            run="run",
            model=ws.folder.structure,
            settings=ws.one_step(),
            what=(
                f"{ws.folder.structure.name}, cost one step (the structure's linear parameters "
                "start at the exact optimum of this cost; the ES seeded there keeps it or finds "
                "better)"
            ),
        )
