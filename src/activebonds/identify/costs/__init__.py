"""The costs a fit minimises, by name (``FitSettings.cost``, ``fit --cost``), each one module
behind the :class:`~.base.Cost` protocol: the restart cost (:mod:`.restart_cost`, the paper's,
at a horizon) and multiple shooting (:mod:`.shooting_cost`). The refinement, the uncertainty
and the integrator check call a cost; none asks which one it is. A new cost is one module and
one line in :data:`COSTS`, or :func:`register` (:func:`registered` for a ``with`` block) from
outside. Which cost a fit on a recording should use is :mod:`.choice`'s."""

from __future__ import annotations

from ...registry import Registry
from .base import Cost
from .restart_cost import RESTART
from .shooting_cost import SHOOTING

COSTS: Registry[Cost] = Registry("cost", (RESTART, SHOOTING))
DEFAULT = RESTART.name
register, unregister, registered = COSTS.register, COSTS.unregister, COSTS.registered
get, names = COSTS.find, COSTS.names


__all__ = ["DEFAULT", "Cost", "get", "names", "register", "registered"]
