"""Post-fit stages, the third registry beside bond kinds and strategies: name -> stage, in
the order they run (:mod:`.base` for the protocol). A new stage is one module and one line in
:data:`_STAGES`, or :func:`register` (:func:`registered` for a ``with`` block) from outside."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from . import baselines, refinement, uncertainty, validation
from .base import Fit, Outcome, PostFitStage

_STAGES: dict[str, PostFitStage] = {
    s.name: s for s in (refinement.STAGE, baselines.STAGE, uncertainty.STAGE, validation.STAGE)
}


def register(stage: PostFitStage) -> PostFitStage:
    """Add a stage (after the ones registered before it)."""
    if stage.name in _STAGES:
        raise ValueError(f"post-fit stage '{stage.name}' is already registered")
    _STAGES[stage.name] = stage
    return stage


def unregister(name: str) -> None:
    del _STAGES[name]


@contextmanager
def registered(stage: PostFitStage) -> Iterator[PostFitStage]:
    """The stage registered inside the ``with`` block only."""
    register(stage)
    try:
        yield stage
    finally:
        unregister(stage.name)


def get(name: str) -> PostFitStage:
    return _STAGES[name]


def names() -> tuple[str, ...]:
    return tuple(_STAGES)


def stages() -> tuple[PostFitStage, ...]:
    return tuple(_STAGES.values())


__all__ = ["Fit", "Outcome", "PostFitStage", "get", "names", "register", "registered", "stages"]
