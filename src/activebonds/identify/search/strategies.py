"""The optimisers a fit can use, by name (``FitSettings.optimizer``, ``fit --optimizer``).

Each entry builds a strategy (:mod:`.strategy`) for a problem from the fit's settings. A new
optimiser is one module implementing the protocol plus one line here.
"""

from __future__ import annotations

from collections.abc import Callable

from .cmaes import CMAES
from .es import PaperES
from .random_search import RandomSearch
from .strategy import Problem, Strategy

BUILDERS: dict[str, Callable[[Problem, object, object], Strategy]] = {
    "es": lambda problem, settings, dtype: PaperES(problem, settings.es(), dtype),
    "random": lambda problem, settings, dtype: RandomSearch(problem, settings.population, dtype),
    "cmaes": lambda p, s, dtype: CMAES(p, s.population, s.sigma_init, dtype),
}


def names() -> tuple[str, ...]:
    return tuple(BUILDERS)


def make(name: str, problem: Problem, settings, dtype) -> Strategy:
    """The strategy ``name`` for ``problem`` with the fit's ``settings``."""
    return BUILDERS[name](problem, settings, dtype)
