"""The paper's self-adaptive evolution strategy, as a strategy (:mod:`.strategy`).

Recipe (one generation, §3.2 of Stanciulescu & Louchet 2000, completed by DESIGN.md §3):

1. each of N children starts from a parent drawn by global tournament; with probability
   ``crossover_rate`` its genes are replaced by the multi-parent crossover per bond type;
2. one mutation variant (``operators.VARIANTS``) per child is applied (mutabilities first):
   with fixed variant rates (the default) child i's variant is fixed, the counts proportional
   to the rates and interleaved (i mod 4 for equal rates: ``operators.plan``), and each child
   draws only the random numbers its variant uses; with ``adapt_variants`` each child draws
   its variant from the adapted rates;
3. children are evaluated (global and local costs; non-finite -> +inf, counted);
4. survivors are selected from parents + children: 10 % elite, the rest random biased to low
   cost, population size constant.

Steps 1-2 are :meth:`PaperES.ask`, 3 is the loop's (:mod:`activebonds.identify.search.evolve`), 4 is
:meth:`PaperES.tell`. Randomness: the key of generation g is ``fold_in(PRNGKey(seed), g)``, so a
run is a pure function of (problem, settings, seed) and does not depend on how it is chunked or
resumed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import operators as ops
from .strategy import COST_COLUMN_NAMES, COST_COLUMNS, Column, Problem, uniform_population


@dataclass(frozen=True)
class ESSettings:
    """Frozen, hashable settings of the ES."""

    population: int = 100
    elite_fraction: float = 0.1
    crossover_rate: float = 0.5
    selection_pressure: float = 4.0
    sigma_init: float = 0.1  # initial mutability, as a fraction of each gene's range
    # crossover_rate: the fraction of children made by crossover (the others are copies of a
    # tournament winner); all children are then mutated.
    sigma_floor: float = 1e-9  # smallest mutability, as a fraction of the range
    variant_probs: tuple[float, ...] = (0.25, 0.25, 0.25, 0.25)  # one per ops.VARIANTS
    adapt_variants: bool = False

    @property
    def n_cross(self) -> int:
        return int(round(self.crossover_rate * self.population))

    @property
    def n_elite(self) -> int:
        return max(1, math.ceil(self.elite_fraction * self.population))


class ESState(NamedTuple):
    genes: jax.Array  # [N, G]
    sigma: jax.Array  # [N, G] mutabilities
    cost: jax.Array  # [N]
    local: jax.Array  # [N, P]
    variant_probs: jax.Array  # [V] rates of the mutation variants (ops.VARIANTS)


class Children(NamedTuple):
    """What :meth:`PaperES.tell` needs to know of the children it asked for."""

    genes: jax.Array  # [N, G]
    sigma: jax.Array  # [N, G]
    variant: jax.Array  # [N] index into ops.VARIANTS
    reference: jax.Array  # [N] the cost each child must beat to count as a success


def _columns() -> tuple[Column, ...]:
    cols = list(COST_COLUMNS)
    for field in ("trials", "successes"):
        for i, v in enumerate(ops.VARIANTS):
            cols.append(Column(f"{field}_{v.name}", field, i, integer=True))
    return tuple(cols)


@dataclass(frozen=True, eq=False)
class PaperES:
    """The paper's ES as a strategy, bound to a problem and its settings."""

    problem: Problem
    settings: ESSettings
    dtype: object = None

    name = "es"
    columns = _columns()
    cost_columns = COST_COLUMN_NAMES

    def init(self, key, evaluate) -> ESState:
        """Population drawn uniformly within the bounds (search space), the problem's
        ``start`` genomes (if any) in its first places; mutabilities at ``sigma_init`` of each
        range."""
        dtype = self.dtype or jnp.result_type(float)
        problem, settings = self.problem, self.settings
        lo, hi = jnp.asarray(problem.lower, dtype), jnp.asarray(problem.upper, dtype)
        genes = uniform_population(key, problem, settings.population, dtype)
        sigma = jnp.broadcast_to(settings.sigma_init * (hi - lo), genes.shape)
        cost, local = evaluate(genes)
        probs = jnp.asarray(settings.variant_probs, dtype)
        return ESState(genes=genes, sigma=sigma, cost=cost, local=local, variant_probs=probs)

    @cached_property
    def plan(self) -> np.ndarray | None:
        """The children's fixed mutation variants (:func:`operators.plan`), or None where the
        variant rates adapt (each child then draws its variant)."""
        if self.settings.adapt_variants:
            return None
        return ops.plan(self.settings.population, self.settings.variant_probs)

    def draw(self, key) -> ops.Noise:
        """The random numbers of one generation (float32): with fixed variant rates, each
        child draws only those its variant uses, spread to the shapes of
        :func:`operators.draw` here, in bulk before the generations run (a gather inside a
        generation would be fused into its every consumer)."""
        shape = np.asarray(self.problem.group_slots).shape
        n, c, g = self.settings.population, self.settings.n_cross, len(self.problem.lower)
        plan = self.plan
        if plan is None:
            return ops.draw(key, n, c, g, shape, jnp.float32)
        planned = ops.draw_planned(key, plan, c, g, shape, jnp.float32)
        return ops.expand(planned, plan, self.settings.variant_probs)

    @property
    def noise_bytes(self) -> int:
        """Memory of one generation's random numbers (float32), to size the chunks."""
        n, g = self.settings.population, len(self.problem.lower)
        t, s = np.asarray(self.problem.group_slots).shape
        return 4 * (n * (2 + 4 + 2 * g + 1) + 2 * self.settings.n_cross * t * s + 2 * n)

    def ask(self, nz: ops.Noise, state: ESState):
        """Steps 1 and 2: parents, crossover per bond type, one mutation variant per child."""
        problem, settings = self.problem, self.settings
        n = settings.population
        dtype = state.genes.dtype
        bounds = ops.Bounds(jnp.asarray(problem.lower, dtype), jnp.asarray(problem.upper, dtype))
        gene_group = jnp.asarray(problem.gene_group)
        slots = jnp.asarray(problem.group_slots)

        # 1. parents, crossover per bond type
        # children [0, C) by crossover, [C, N) copies of their first parent. Each child's
        # variant-2 bias and success count refer to its own parents: the copied parent, or
        # for a crossover child the parents chosen per slot (their local cost at the slot's
        # particle; a success beats the best of them).
        first = ops.tournament(nz.parent, state.cost)
        c = settings.n_cross
        genes, sigma = state.genes[first], state.sigma[first]
        per_slot = ops.slot_costs(state.local[first], slots)
        reference = state.cost[first]
        if c > 0:
            cross_genes, cross_sigma, parents = ops.crossover(
                nz.cross, state.genes, state.sigma, state.local, slots, gene_group
            )
            genes = jnp.concatenate([cross_genes, genes[c:]])
            sigma = jnp.concatenate([cross_sigma, sigma[c:]])
            cross_slot = ops.crossover_slot_costs(state.local, parents, slots)
            per_slot = jnp.concatenate([cross_slot, per_slot[c:]])
            cross_ref = ops.crossover_reference(state.cost, parents, slots)
            reference = jnp.concatenate([cross_ref, reference[c:]])

        # 2. mutation: one variant per child
        probs = jnp.broadcast_to(state.variant_probs, (n, ops.N_VARIANTS))
        variant = ops.choose(nz.variant, probs)
        group_prob = ops.group_bias(per_slot, slots, slots.shape[0])
        genes, sigma = ops.mutate(
            nz, genes, sigma, variant, group_prob, gene_group, bounds, settings.sigma_floor
        )
        return genes, Children(genes, sigma, variant, reference)

    def tell(self, nz: ops.Noise, state: ESState, children: Children, cost, local):
        """Step 4: survivors from parents + children, and the generation's history row."""
        settings = self.settings
        n = settings.population
        dtype = state.genes.dtype
        # 4. selection from parents + children (3, the evaluation, is the loop's)
        onehot = jax.nn.one_hot(children.variant, ops.N_VARIANTS, dtype=jnp.int32)
        trials = onehot.sum(0)
        successes = (onehot * (cost < children.reference)[:, None]).sum(0)

        all_cost = jnp.concatenate([state.cost, cost])
        keep = ops.select(nz.gumbel, all_cost, n, settings.n_elite, settings.selection_pressure)
        pool_genes = jnp.concatenate([state.genes, children.genes])
        pool_sigma = jnp.concatenate([state.sigma, children.sigma])
        pool_local = jnp.concatenate([state.local, local])
        new_cost = all_cost[keep]

        probs = state.variant_probs
        if settings.adapt_variants:
            rate = (successes + 1.0) / (trials + 2.0)
            probs = 0.9 * probs + 0.1 * rate / rate.sum()
            probs = jnp.maximum(probs, 0.05)
            probs = probs / probs.sum()

        new_state = ESState(
            genes=pool_genes[keep],
            sigma=pool_sigma[keep],
            cost=new_cost,
            local=pool_local[keep],
            variant_probs=probs.astype(dtype),
        )
        finite = jnp.isfinite(new_cost)
        # the median from float32 top-k (fast path on CPU), gathered back in full precision
        half = new_cost[jax.lax.top_k(-new_cost.astype(jnp.float32), n // 2 + 1)[1]]
        row = {
            "best": jnp.min(new_cost),
            "median": half[(n - 1) // 2] if n % 2 else 0.5 * (half[n // 2 - 1] + half[n // 2]),
            "worst": jnp.max(jnp.where(finite, new_cost, -jnp.inf)),  # worst finite survivor
            "trials": trials,  # [V] children per variant
            "successes": successes,  # [V] children better than their own parent(s)
        }
        return new_state, row

    def best(self, state: ESState):
        """(genome, cost, local costs) of the best individual."""
        i = jnp.argmin(state.cost)
        return state.genes[i], state.cost[i], state.local[i]


__all__ = ["Children", "ESSettings", "ESState", "PaperES", "Problem"]
