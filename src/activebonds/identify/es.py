"""The paper's self-adaptive evolution strategy as pure functions over a state pytree.

Recipe (one generation, §3.2 of Stanciulescu & Louchet 2000, completed by DESIGN.md §3):

1. each of N children starts from a parent drawn by global tournament; with probability
   ``crossover_rate`` its genes are replaced by the multi-parent crossover per bond type;
2. one of four mutation variants is drawn per child and applied (mutabilities first);
3. children are evaluated (global and local costs; non-finite -> +inf, counted);
4. survivors are selected from parents + children: 10 % elite, the rest random biased to low
   cost, population size constant.

Randomness: the key of generation g is ``fold_in(PRNGKey(seed), g)``, so a run is a pure
function of (problem, settings, seed) and does not depend on how it is chunked or resumed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import operators as ops


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
    variant_probs: tuple[float, float, float, float] = (0.25, 0.25, 0.25, 0.25)
    adapt_variants: bool = False

    @property
    def n_cross(self) -> int:
        return int(round(self.crossover_rate * self.population))

    @property
    def n_elite(self) -> int:
        return max(1, math.ceil(self.elite_fraction * self.population))


class Problem(NamedTuple):
    """What the ES needs of an identification problem (static for a whole run)."""

    evaluate: object  # genome [G] -> (cost, local [P]); vmapped inside
    lower: np.ndarray  # [G] search-space bounds
    upper: np.ndarray
    gene_group: np.ndarray  # [G] bond-type group of each gene
    group_slots: np.ndarray  # [T, S] extremity particles of each group, -1 padded
    start: np.ndarray | None = None  # [K, G] genomes placed first in the initial population


class ESState(NamedTuple):
    genes: jax.Array  # [N, G]
    sigma: jax.Array  # [N, G] mutabilities
    cost: jax.Array  # [N]
    local: jax.Array  # [N, P]
    variant_probs: jax.Array  # [4]
    generation: jax.Array  # int32 scalar: generations done
    failed_total: jax.Array  # int32: non-finite evaluations so far


class GenerationRow(NamedTuple):
    best: jax.Array
    median: jax.Array
    worst: jax.Array  # worst finite cost among survivors
    failed: jax.Array  # children whose simulation went non-finite
    trials: jax.Array  # [4] children per variant
    successes: jax.Array  # [4] children better than their own parent(s)


def _evaluate(problem: Problem, genes):
    return jax.vmap(problem.evaluate)(genes)


def _finite_or_inf(cost, local):
    """A candidate whose simulation went non-finite costs +inf, globally and locally."""
    bad = ~jnp.isfinite(cost)
    local = jnp.where(bad[:, None] | ~jnp.isfinite(local), jnp.inf, local)
    return jnp.where(bad, jnp.inf, cost), local


def init(key, problem: Problem, settings: ESSettings, dtype=None) -> ESState:
    """Population drawn uniformly within the bounds (search space), the problem's ``start``
    genomes (if any) in its first places; mutabilities at ``sigma_init`` of each range."""
    dtype = dtype or jnp.result_type(float)
    lo, hi = jnp.asarray(problem.lower, dtype), jnp.asarray(problem.upper, dtype)
    n = settings.population
    genes = lo + (hi - lo) * jax.random.uniform(key, (n, lo.shape[0]), dtype)
    if problem.start is not None:
        start = jnp.clip(jnp.asarray(problem.start, dtype)[:n], lo, hi)
        genes = genes.at[: start.shape[0]].set(start)
    sigma = jnp.broadcast_to(settings.sigma_init * (hi - lo), genes.shape)
    cost, local = _finite_or_inf(*_evaluate(problem, genes))
    return ESState(
        genes=genes,
        sigma=sigma,
        cost=cost,
        local=local,
        variant_probs=jnp.asarray(settings.variant_probs, dtype),
        generation=jnp.asarray(0, jnp.int32),
        failed_total=jnp.sum(~jnp.isfinite(cost)).astype(jnp.int32),
    )


def noise(base_key, generation_index, problem: Problem, settings: ESSettings, dtype):
    """The random numbers of one generation: a pure function of (seed key, generation)."""
    key = jax.random.fold_in(base_key, generation_index)
    shape = np.asarray(problem.group_slots).shape
    return ops.draw(key, settings.population, settings.n_cross, len(problem.lower), shape, dtype)


def generation(nz: ops.Noise, state: ESState, problem: Problem, settings: ESSettings):
    """One generation from its random numbers. Returns (new state, row of history)."""
    n = settings.population
    dtype = state.genes.dtype
    bounds = ops.Bounds(jnp.asarray(problem.lower, dtype), jnp.asarray(problem.upper, dtype))
    gene_group = jnp.asarray(problem.gene_group)
    slots = jnp.asarray(problem.group_slots)

    # 1. parents, crossover per bond type
    # children [0, C) by crossover, [C, N) copies of their first parent. Each child's
    # variant-2 bias and success count refer to its own parents: the copied parent, or for a
    # crossover child the parents chosen per slot (their local cost at the slot's particle;
    # a success beats the best of them).
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
    variant = ops.choose(nz.variant, jnp.broadcast_to(state.variant_probs, (n, ops.N_VARIANTS)))
    group_prob = ops.group_bias(per_slot, slots, slots.shape[0])
    genes, sigma = ops.mutate(
        nz, genes, sigma, variant, group_prob, gene_group, bounds, settings.sigma_floor
    )

    # 3. evaluation
    cost, local = _finite_or_inf(*_evaluate(problem, genes))
    failed = jnp.sum(~jnp.isfinite(cost)).astype(jnp.int32)
    onehot = jax.nn.one_hot(variant, ops.N_VARIANTS, dtype=jnp.int32)
    trials = onehot.sum(0)
    successes = (onehot * (cost < reference)[:, None]).sum(0)

    # 4. selection from parents + children
    all_cost = jnp.concatenate([state.cost, cost])
    keep = ops.select(nz.gumbel, all_cost, n, settings.n_elite, settings.selection_pressure)
    pool_genes = jnp.concatenate([state.genes, genes])
    pool_sigma = jnp.concatenate([state.sigma, sigma])
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
        generation=state.generation + 1,
        failed_total=state.failed_total + failed,
    )
    finite = jnp.isfinite(new_cost)
    # the median from float32 top-k (fast path on CPU), gathered back in full precision
    half = new_cost[jax.lax.top_k(-new_cost.astype(jnp.float32), n // 2 + 1)[1]]
    row = GenerationRow(
        best=jnp.min(new_cost),
        median=half[(n - 1) // 2] if n % 2 else 0.5 * (half[n // 2 - 1] + half[n // 2]),
        worst=jnp.max(jnp.where(finite, new_cost, -jnp.inf)),
        failed=failed,
        trials=trials,
        successes=successes,
    )
    return new_state, row


def run(base_key, state: ESState, problem: Problem, settings: ESSettings, n_generations: int, stop):
    """``n_generations`` generations in one compiled ``lax.scan``; generations at or beyond
    ``stop`` leave the state unchanged (so one compiled chunk length serves a whole run).

    The random numbers of the whole chunk are drawn first, in bulk (vectorised over
    generations), then read by the scan; each generation's numbers depend only on the seed
    key and the generation index, so results do not depend on the chunk length."""
    indices = state.generation + jnp.arange(n_generations, dtype=jnp.int32)
    noises = jax.vmap(lambda g: noise(base_key, g, problem, settings, jnp.float32))(indices)

    def body(s, nz):
        new, row = generation(nz, s, problem, settings)
        active = s.generation < stop
        s = jax.tree.map(lambda a, b: jnp.where(active, a, b), new, s)
        return s, (row, active)

    return jax.lax.scan(body, state, noises)


def noise_bytes(problem: Problem, settings: ESSettings) -> int:
    """Memory of one generation's random numbers (float32), to size the chunks."""
    n, g = settings.population, len(problem.lower)
    t, s = np.asarray(problem.group_slots).shape
    return 4 * (n * (2 + 4 + 2 * g + 1) + 2 * settings.n_cross * t * s + 2 * n)


def best(state: ESState):
    """(genome, cost, local costs) of the best individual."""
    i = jnp.argmin(state.cost)
    return state.genes[i], state.cost[i], state.local[i]
