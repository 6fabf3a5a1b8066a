"""CMA-ES (evosax's ``CMA_ES``) as a strategy (:mod:`.strategy`).

The search runs in a normalised space: a genome is ``g = lower + (upper - lower) * u`` with
``u`` in [0, 1]. evosax samples ``u``; each sample is folded back into [0, 1] as the paper's ES
folds its genes (``operators.reflect``: reflection once, then clip), so every evaluated
candidate lies within the bounds, and evosax is told the costs of its own samples. The mean
starts at the best of the problem's ``start`` genomes (else at the centre of the box), the step
size at ``sigma_init`` (a fraction of each gene's range).

Randomness: ``draw(key)`` returns the generation's key itself (``fold_in(seed key, g)``), the
one evosax's ``ask`` consumes, so a run is a pure function of (problem, settings, seed) and
does not depend on chunking or resuming.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from . import operators as ops
from .strategy import COST_COLUMN_NAMES, COST_COLUMNS, Column, Problem


class CMAESState(NamedTuple):
    es: Any  # evosax's CMA-ES state (unit space), every leaf an array of a fixed dtype
    genes: jax.Array  # [G] best genome so far (within the bounds)
    cost: jax.Array  # its cost
    local: jax.Array  # [P] its local costs


class Asked(NamedTuple):
    """What :meth:`CMAES.tell` needs of the candidates it asked for."""

    unit: jax.Array  # [N, G] evosax's samples (unit space, before folding)
    genes: jax.Array  # [N, G] the evaluated genomes
    es: Any  # evosax's state after ask (its eigendecomposition)


@cache
def _algorithm(population: int, n_genes: int, dtype_name: str, x64: bool):
    from evosax.algorithms import CMA_ES

    with jax.ensure_compile_time_eval():  # built once, outside any trace
        return CMA_ES(population_size=population, solution=jnp.zeros(n_genes, dtype_name))


@dataclass(frozen=True, eq=False)
class CMAES:
    """evosax's CMA-ES, bound to a problem; ``sigma_init`` is a fraction of the ranges."""

    problem: Problem
    population: int
    sigma_init: float = 0.1
    dtype: object = None

    name = "cmaes"
    columns = (*COST_COLUMNS, Column("sigma", "sigma"))
    cost_columns = COST_COLUMN_NAMES

    @property
    def noise_bytes(self) -> int:
        return 8  # one PRNG key per generation

    def _dtype(self):
        return jnp.dtype(self.dtype or jnp.result_type(float))

    def _algo(self):
        dtype = self._dtype()
        return _algorithm(
            self.population, len(self.problem.lower), dtype.name, jax.config.jax_enable_x64
        )

    def _params(self):
        params = self._algo().default_params
        return params.replace(std_init=jnp.asarray(self.sigma_init, self._dtype()))

    def _box(self):
        dtype = self._dtype()
        lo = jnp.asarray(self.problem.lower, dtype)
        return lo, jnp.asarray(self.problem.upper, dtype) - lo

    def _fixed(self, es):
        """evosax's state with every leaf an array of a fixed dtype (checkpoints, scan)."""
        dtype = self._dtype()
        return es.replace(
            best_fitness=jnp.asarray(es.best_fitness, dtype),
            generation_counter=jnp.asarray(es.generation_counter, jnp.int32),
            **{
                f: jnp.asarray(getattr(es, f), dtype)
                for f in ("mean", "std", "p_std", "p_c", "C", "B", "D", "best_solution")
            },
        )

    def init(self, key, evaluate) -> CMAESState:
        """Evaluates the start genomes (or the centre); evosax's mean at the best of them."""
        dtype = self._dtype()
        lo, span = self._box()
        if self.problem.start is not None:
            unit = jnp.clip((jnp.asarray(self.problem.start, dtype) - lo) / span, 0.0, 1.0)
        else:
            unit = jnp.full((1, lo.shape[0]), 0.5, dtype)
        genes = lo + span * unit
        cost, local = evaluate(genes)
        i = jnp.argmin(cost)
        es = self._fixed(self._algo().init(key, unit[i], self._params()))
        return CMAESState(es, genes[i], cost[i], local[i])

    def draw(self, key):
        return key

    def ask(self, key, state: CMAESState):
        lo, span = self._box()
        unit, es = self._algo().ask(key, state.es, self._params())
        unit = unit.astype(lo.dtype)
        folded = ops.reflect(unit, ops.Bounds(jnp.zeros_like(lo), jnp.ones_like(lo)))
        genes = lo + span * folded
        return genes, Asked(unit, genes, self._fixed(es))

    def tell(self, key, state: CMAESState, asked: Asked, cost, local):
        fitness = jnp.where(jnp.isfinite(cost), cost, jnp.finfo(cost.dtype).max)
        es, _ = self._algo().tell(key, asked.unit, fitness, asked.es, self._params())
        i = jnp.argmin(cost)
        better = cost[i] < state.cost
        new = CMAESState(
            self._fixed(es),
            jnp.where(better, asked.genes[i], state.genes),
            jnp.where(better, cost[i], state.cost),
            jnp.where(better, local[i], state.local),
        )
        finite = jnp.isfinite(cost)
        row = {
            "best": new.cost,  # best so far
            "median": jnp.median(cost),  # of this generation's candidates
            "worst": jnp.max(jnp.where(finite, cost, -jnp.inf)),  # worst finite candidate
            "sigma": new.es.std,  # evosax's step size, as a fraction of the ranges
        }
        return new, row

    def best(self, state: CMAESState):
        return state.genes, state.cost, state.local


__all__ = ["CMAES", "CMAESState"]
