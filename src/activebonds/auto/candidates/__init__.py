"""The candidate models of ``activebonds auto``'s fit step, in the order they are tried: each
proposes a model against the one kept so far, which is fitted and judged
(:mod:`~activebonds.auto.judge`) and kept where the judge finds it better. A new candidate is
one module (a class with ``name`` and ``propose``: :class:`~.base.Candidate`) and one line
here, or :meth:`CANDIDATES.registered <activebonds.registry.Registry.registered>` from
outside."""

from __future__ import annotations

from ...registry import Registry
from .base import MAX_SHOT, SHOOTING, Candidate, Proposal, Tried
from .gait import GaitCandidate
from .ground import GroundCandidate
from .masses import MassesCandidate
from .shot import ShotCandidate
from .structure import StructureCandidate
from .walk import WalkCandidate

CANDIDATES: Registry[Candidate] = Registry(
    "auto candidate",
    [
        StructureCandidate(),
        GroundCandidate(),
        MassesCandidate(),
        GaitCandidate(),
        WalkCandidate(),
        ShotCandidate(),
    ],
)

__all__ = ["CANDIDATES", "MAX_SHOT", "SHOOTING", "Candidate", "Proposal", "Tried"]
