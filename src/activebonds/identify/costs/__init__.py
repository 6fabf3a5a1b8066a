"""The costs a fit minimises, by name (``FitSettings.cost``, ``fit --cost``), each one module
behind the :class:`~.base.Cost` protocol: the restart cost (:mod:`.restart_cost`, the paper's,
at a horizon) and multiple shooting (:mod:`.shooting_cost`). The refinement, the uncertainty
and the integrator check call a cost; none asks which one it is. A new cost is one module and
one line in :data:`_COSTS`, or :func:`register` (:func:`registered` for a ``with`` block) from
outside. Which cost a fit on a recording should use is :mod:`.choice`'s."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from .base import Cost
from .restart_cost import RESTART
from .shooting_cost import SHOOTING

_COSTS: dict[str, Cost] = {c.name: c for c in (RESTART, SHOOTING)}
DEFAULT = RESTART.name


def names() -> tuple[str, ...]:
    return tuple(_COSTS)


def get(name: str) -> Cost:
    """The cost called ``name``; a ValueError naming the known ones otherwise."""
    try:
        return _COSTS[name]
    except KeyError:
        raise ValueError(f"unknown cost {name!r}; choose one of {', '.join(_COSTS)}") from None


def register(cost: Cost) -> None:
    """Add ``cost`` under its name (a name already taken is refused)."""
    if cost.name in _COSTS:
        raise ValueError(f"a cost named {cost.name!r} is registered already")
    _COSTS[cost.name] = cost


@contextmanager
def registered(cost: Cost) -> Iterator[Cost]:
    """``cost`` registered for the ``with`` block, removed after it."""
    register(cost)
    try:
        yield cost
    finally:
        _COSTS.pop(cost.name, None)


__all__ = ["DEFAULT", "Cost", "get", "names", "register", "registered"]
