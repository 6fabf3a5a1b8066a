"""Evolutionary operators of the paper's self-adaptive ES (Stanciulescu & Louchet 2000, §3.2.2).

Every operator is a pure function of arrays and an explicit PRNG key, vectorised over the
population (no Python loop over individuals or bonds). Shapes: N individuals, G genes, P
particles, T bond-type groups, S extremity slots per group.

The paper names four concurrent mutation variants without defining them; the four below are
ours (DESIGN.md §3): (1) all genes, (2) one bond type's genes, biased to the worst local cost,
(3) all genes with mutabilities frozen, (4) a Cauchy jump of a single gene.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

N_VARIANTS = 4


class Bounds(NamedTuple):
    lower: jax.Array  # [G] search space
    upper: jax.Array  # [G]


def randindex(key, shape, n: int):
    """Uniform integers in [0, n): floor(u n) of a uniform u (cheaper than randint on CPU;
    the bias is below 2^-20 for the population sizes used here)."""
    u = jax.random.uniform(key, shape)
    return jnp.minimum((u * n).astype(jnp.int32), n - 1)


def choose(key, probs):
    """One category per row of ``probs`` [..., K] by inverse CDF (one uniform per row)."""
    u = jax.random.uniform(key, probs.shape[:-1] + (1,), probs.dtype)
    cdf = jnp.cumsum(probs, axis=-1)
    return jnp.minimum(jnp.sum(cdf < u * cdf[..., -1:], axis=-1), probs.shape[-1] - 1)


def tournament(key, fitness, n: int):
    """Indices of ``n`` binary-tournament winners (lower fitness wins): a random choice
    biased to good individuals. ``fitness`` is [N]."""
    a, b = randindex(key, (2, n), fitness.shape[0])
    return jnp.where(fitness[b] < fitness[a], b, a)


def local_tournament(key, local, slots):
    """For each child, group and slot, a parent biased to a low *local* cost at the slot's
    particle (§3.2.2 crossover). local [N, P], slots [T, S] (-1 = padding) -> [n, T, S]."""
    n = local.shape[0]
    a, b = randindex(key, (2, n) + slots.shape, n)
    p = jnp.maximum(slots, 0)[None]
    return jnp.where(local[b, p] < local[a, p], b, a)


def crossover(key, genes, sigma, local, slots, gene_group):
    """Multi-parent crossover per bond type (§3.2.2).

    For each bond type, for each occurrence, for each particle at its extremity, a parent is
    picked with a bias to parents whose local cost at that particle is low; the child's genes
    of that bond type are the mean of the chosen parents' genes (mutabilities: geometric mean).
    Returns child genes and mutabilities [N, G].
    """
    parents = local_tournament(key, local, slots)  # [N, T, S]
    coef = crossover_weights(slots, gene_group, genes.shape[1]).astype(genes.dtype)
    # Whole-row gathers, then a weighted sum that keeps each gene's own group: [N, T, S, G].
    child = jnp.einsum("ntsg,tsg->ng", genes[parents], coef)
    child_sigma = jnp.exp(jnp.einsum("ntsg,tsg->ng", jnp.log(sigma)[parents], coef))
    return child, child_sigma


def crossover_weights(slots, gene_group, n_genes: int):
    """[T, S, G]: 1/(slots of group t) where gene g belongs to group t and slot s is used."""
    valid = (slots >= 0).astype(jnp.float32)
    per_group = valid / jnp.maximum(valid.sum(-1, keepdims=True), 1.0)
    member = (gene_group[None, :] == jnp.arange(slots.shape[0])[:, None]).astype(jnp.float32)
    return per_group[:, :, None] * member[:, None, :]


def group_bias(local, slots, n_groups):
    """Probability of each bond type for variant (2): proportional to the mean local cost of
    its particles, so badly fitted parts of the body get mutated more. local [N, P] -> [N, T]."""
    valid = slots >= 0
    per_slot = jnp.where(valid[None], local[:, jnp.maximum(slots, 0)], 0.0)
    score = per_slot.sum(-1) / jnp.maximum(valid.sum(-1), 1)[None]
    score = jnp.where(jnp.isfinite(score), score, 0.0)
    total = score.sum(-1, keepdims=True)
    uniform = jnp.full_like(score, 1.0 / n_groups)
    return jnp.where(total > 0, score / jnp.where(total > 0, total, 1.0), uniform)


def mutate(key, genes, sigma, variant, group_prob, gene_group, bounds: Bounds, sigma_floor):
    """Apply the drawn mutation variant to each child.

    Mutabilities self-adapt log-normally before the genes move (Schwefel:
    tau' = 1/sqrt(2n), tau = 1/sqrt(2 sqrt(n))). variant [N] in 0..3 (paper numbering 1..4).
    """
    n, g = genes.shape
    tau_global = 1.0 / jnp.sqrt(2.0 * g)
    tau_local = 1.0 / jnp.sqrt(2.0 * jnp.sqrt(g))
    k_global, k_local, k_step, k_group, k_gene, k_cauchy = jax.random.split(key, 6)
    z0 = jax.random.normal(k_global, (n, 1), genes.dtype)
    zi = jax.random.normal(k_local, (n, g), genes.dtype)
    step = jax.random.normal(k_step, (n, g), genes.dtype)
    group = choose(k_group, group_prob)  # [N]
    one_gene = randindex(k_gene, (n,), g)
    cauchy = jax.random.cauchy(k_cauchy, (n,), genes.dtype)

    in_group = gene_group[None, :] == group[:, None]  # [N, G]
    single = jnp.arange(g)[None, :] == one_gene[:, None]
    v = variant[:, None]
    # Which genes each variant touches, and whether it adapts the mutabilities there.
    touched = jnp.where(v == 1, in_group, jnp.where(v == 3, single, True))
    adapt = touched & ((v == 0) | (v == 1))

    span = bounds.upper - bounds.lower
    new_sigma = jnp.where(adapt, sigma * jnp.exp(tau_global * z0 + tau_local * zi), sigma)
    new_sigma = jnp.clip(new_sigma, sigma_floor * span, span)
    delta = jnp.where(v == 3, new_sigma * cauchy[:, None], new_sigma * step)
    moved = jnp.where(touched, genes + delta, genes)
    return reflect(moved, bounds), new_sigma


def reflect(genes, bounds: Bounds):
    """Fold genes back into [lower, upper] (reflection once, then clip)."""
    lo, hi = bounds.lower, bounds.upper
    genes = jnp.where(genes < lo, 2 * lo - genes, genes)
    genes = jnp.where(genes > hi, 2 * hi - genes, genes)
    return jnp.clip(genes, lo, hi)


def select(key, cost, n_keep: int, n_elite: int, pressure: float):
    """Survivors: the ``n_elite`` best unchanged (elitism, so the best cost never rises), the
    rest drawn at random without replacement, biased to low global cost (rank-based weights,
    Gumbel top-k). Non-finite costs rank below every finite one and are only drawn when fewer
    finite candidates than places exist. cost [M] -> indices [n_keep]."""
    m = cost.shape[0]
    _, order = jax.lax.top_k(-cost, m)  # full ordering, best first (faster than argsort on CPU)
    rank = jnp.zeros(m, jnp.int32).at[order].set(jnp.arange(m, dtype=jnp.int32))
    elite = order[:n_elite]
    logits = -pressure * rank.astype(cost.dtype) / m
    logits = jnp.where(jnp.isfinite(cost), logits, -1e6 - rank.astype(cost.dtype))
    logits = jnp.where(rank < n_elite, -jnp.inf, logits)
    gumbel = jax.random.gumbel(key, (m,), cost.dtype)
    _, rest = jax.lax.top_k(logits + gumbel, n_keep - n_elite)
    return jnp.concatenate([elite, rest])
