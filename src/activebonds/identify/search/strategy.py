"""What an optimiser must provide to run under :mod:`activebonds.identify.search.evolve`.

A strategy is an object bound to one :class:`Problem` (bounds, bond-type groups, start genomes)
and its settings, in the style of evosax and optax: pure functions over a state pytree.

* ``init(key, evaluate) -> state``: the first population, evaluated with ``evaluate``;
* ``draw(key) -> noise``: the random numbers of one generation (drawn in bulk, per chunk, by the
  loop; ``key`` is ``fold_in(seed key, generation)``, so results do not depend on chunking);
* ``ask(noise, state) -> (genes [N, G], aux)``: the candidates to evaluate;
* ``tell(noise, state, aux, cost [N], local [N, P]) -> (state, row)``: the new state and the
  generation's history row, a dict of scalars or small vectors;
* ``best(state) -> (genome [G], cost, local [P])``;
* ``columns``: the history columns its rows fill, as ``(name, field, index)`` triples; the
  cost columns among them (``cost_columns``) are shown to people through the cost's display;
* ``noise_bytes``: memory of one generation's random numbers, to size the chunks.

The loop evaluates the candidates (vmapped, non-finite -> +inf), counts failures and
generations, and scans many generations in one compiled call. Candidates' costs are sums of
squares; lower is better.
"""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol

import jax
import jax.numpy as jnp
import numpy as np


class Problem(NamedTuple):
    """What a strategy needs of an identification problem (static for a whole run)."""

    evaluate: object  # genome [G] -> (cost, local [P]); vmapped by the loop
    lower: np.ndarray  # [G] search-space bounds
    upper: np.ndarray
    gene_group: np.ndarray  # [G] bond-type group of each gene
    group_slots: np.ndarray  # [T, S] extremity particles of each group, -1 padded
    start: np.ndarray | None = None  # [K, G] genomes placed first in the initial population
    # genes [N, G] -> (cost [N], local [N, P]) for a whole population at once, where a faster
    # form than vmapping ``evaluate`` exists (the one-step cost: identify/search/population_cost.py)
    evaluate_population: object = None


class Column(NamedTuple):
    """One history column: its name, the row field it comes from and, for vector fields,
    which entry."""

    name: str
    field: str
    index: int | None = None
    integer: bool = False


# The cost columns every strategy's rows fill (fields "best", "median" and "worst").
COST_COLUMNS = (
    Column("best_cost", "best"),
    Column("median_cost", "median"),
    Column("worst_cost", "worst"),
)
COST_COLUMN_NAMES = tuple(c.name for c in COST_COLUMNS)


class Strategy(Protocol):
    name: str
    columns: tuple[Column, ...]
    cost_columns: tuple[str, ...]  # names of the columns that hold costs (sums of squares)

    def init(self, key, evaluate) -> Any: ...

    def draw(self, key) -> Any: ...

    def ask(self, noise, state) -> tuple[Any, Any]: ...

    def tell(self, noise, state, aux, cost, local) -> tuple[Any, dict]: ...

    def best(self, state) -> tuple[Any, Any, Any]: ...

    @property
    def noise_bytes(self) -> int: ...


def finite_or_inf(cost, local):
    """A candidate whose simulation went non-finite costs +inf, globally and locally."""
    bad = ~jnp.isfinite(cost)
    local = jnp.where(bad[:, None] | ~jnp.isfinite(local), jnp.inf, local)
    return jnp.where(bad, jnp.inf, cost), local


def uniform_population(key, problem: Problem, n: int, dtype):
    """``n`` genomes uniform within the bounds, the problem's ``start`` genomes first."""
    lo, hi = jnp.asarray(problem.lower, dtype), jnp.asarray(problem.upper, dtype)
    genes = lo + (hi - lo) * jax.random.uniform(key, (n, lo.shape[0]), dtype)
    if problem.start is not None:
        start = jnp.clip(jnp.asarray(problem.start, dtype)[:n], lo, hi)
        genes = genes.at[: start.shape[0]].set(start)
    return genes
