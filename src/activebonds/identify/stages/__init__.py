"""Post-fit stages, the third registry beside bond kinds and strategies: name -> stage, in
the order they run (:mod:`.base` for the protocol). A new stage is one module and one line in
:data:`STAGES`, or :func:`register` (:func:`registered` for a ``with`` block) from outside."""

from __future__ import annotations

from ...registry import Registry
from . import baselines, refinement, uncertainty, validation
from .base import Fit, Outcome, PostFitStage

STAGES: Registry[PostFitStage] = Registry(
    "post-fit stage", (refinement.STAGE, baselines.STAGE, uncertainty.STAGE, validation.STAGE)
)
register, unregister, registered = STAGES.register, STAGES.unregister, STAGES.registered
get, names, stages = STAGES.get, STAGES.names, STAGES.entries


__all__ = ["Fit", "Outcome", "PostFitStage", "get", "names", "register", "registered", "stages"]
