"""Pure random search: a baseline strategy (and the smallest example of the protocol).

Every generation draws ``population`` genomes uniformly within the bounds and keeps the best
genome seen so far. It uses no information from earlier generations, so any method that
learns should beat it at equal evaluations.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp

from .strategy import COST_COLUMN_NAMES, COST_COLUMNS, Problem, uniform_population


class SearchState(NamedTuple):
    genes: jax.Array  # [G] best genome so far
    cost: jax.Array  # best cost so far
    local: jax.Array  # [P] its local costs


@dataclass(frozen=True, eq=False)
class RandomSearch:
    problem: Problem
    population: int
    dtype: object = None

    name = "random"
    columns = COST_COLUMNS
    cost_columns = COST_COLUMN_NAMES

    @property
    def noise_bytes(self) -> int:
        return 4 * self.population * len(self.problem.lower)

    def _genes(self, u):
        dtype = self.dtype or jnp.result_type(float)
        lo = jnp.asarray(self.problem.lower, dtype)
        hi = jnp.asarray(self.problem.upper, dtype)
        return lo + (hi - lo) * u.astype(dtype)

    def init(self, key, evaluate) -> SearchState:
        dtype = self.dtype or jnp.result_type(float)
        genes = uniform_population(key, self.problem, self.population, dtype)
        cost, local = evaluate(genes)
        i = jnp.argmin(cost)
        return SearchState(genes[i], cost[i], local[i])

    def draw(self, key):
        return jax.random.uniform(key, (self.population, len(self.problem.lower)), jnp.float32)

    def ask(self, u, state: SearchState):
        genes = self._genes(u)
        return genes, genes

    def tell(self, u, state: SearchState, genes, cost, local):
        i = jnp.argmin(cost)
        better = cost[i] < state.cost
        new = SearchState(
            jnp.where(better, genes[i], state.genes),
            jnp.where(better, cost[i], state.cost),
            jnp.where(better, local[i], state.local),
        )
        finite = jnp.isfinite(cost)
        row = {
            "best": new.cost,
            "median": jnp.median(cost),
            "worst": jnp.max(jnp.where(finite, cost, -jnp.inf)),
        }
        return new, row

    def best(self, state: SearchState):
        return state.genes, state.cost, state.local
