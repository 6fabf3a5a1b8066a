"""Evolutionary operators of the paper's self-adaptive ES (Stanciulescu & Louchet 2000, §3.2.2).

Every operator is a pure function of arrays and an explicit PRNG key, vectorised over the
population (no Python loop over individuals or bonds). Shapes: N individuals, G genes, P
particles, T bond-type groups, S extremity slots per group.

The paper names four concurrent mutation variants without defining them; :data:`VARIANTS`
holds the four of DESIGN.md §3 as one table, from which the mutation masks, the per-variant
counts, the history columns and the report's labels are derived.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import rng


class Variant(NamedTuple):
    """One mutation variant: what it moves, how, and whose choice it is."""

    name: str  # short name, used in history columns (``trials_<name>``)
    label: str  # for people (report legends)
    genes: str  # which genes move: "all", "group" (one bond type's) or "one"
    adapts: bool  # whether the mutabilities self-adapt before the genes move
    step: str  # distribution of the step, scaled by the mutability: "normal" or "cauchy"
    origin: str  # "paper" where the paper specifies the choice, "ours" where DESIGN.md does


VARIANTS = (
    Variant("all", "(1) all genes", "all", True, "normal", "ours"),
    Variant("type", "(2) one bond type, worst first", "group", True, "normal", "ours"),
    Variant("frozen", "(3) all genes, frozen mutabilities", "all", False, "normal", "ours"),
    Variant("jump", "(4) Cauchy jump of one gene", "one", True, "cauchy", "ours"),
)
N_VARIANTS = len(VARIANTS)
_GENES = ("all", "group", "one")


class Bounds(NamedTuple):
    lower: jax.Array  # [G] search space
    upper: jax.Array  # [G]


class Noise(NamedTuple):
    """The random numbers of one generation, drawn up front (``draw``) so that the compiled
    generation only reads them: XLA would otherwise fuse the generator into every consumer
    and recompute it per element. Uniforms are in (0, 1)."""

    parent: jax.Array  # [2, N] uniforms: tournament candidates for the first parent
    cross: jax.Array  # [2, C, T, S] uniforms: local-tournament candidates per slot
    variant: jax.Array  # [N, 1] uniforms
    group: jax.Array  # [N, 1] uniforms: bond type for variant 2
    gene: jax.Array  # [N] uniforms: gene for variant 4
    z0: jax.Array  # [N, 1] normals: global self-adaptation
    zi: jax.Array  # [N, G] normals: per-gene self-adaptation
    step: jax.Array  # [N, G] normals: gene steps
    cauchy: jax.Array  # [N] Cauchy
    gumbel: jax.Array  # [2N] Gumbel, for selection


def draw(
    key, n: int, n_cross: int, n_genes: int, slots_shape: tuple[int, int], dtype=jnp.float32
) -> Noise:
    k = rng.streams(key, 11)
    t, s = slots_shape
    return Noise(
        parent=rng.uniform(k[0], (2, n)),
        cross=rng.uniform(k[1], (2, n_cross, t, s)),
        variant=rng.uniform(k[3], (n, 1)),
        group=rng.uniform(k[4], (n, 1)),
        gene=rng.uniform(k[5], (n,)),
        z0=rng.normal(k[6], (n, 1), dtype),
        zi=rng.normal(k[7], (n, n_genes), dtype),
        step=rng.normal(k[8], (n, n_genes), dtype),
        cauchy=rng.cauchy(k[9], (n,), dtype),
        gumbel=rng.gumbel(k[10], (2 * n,), dtype),
    )


def plan(n: int, probs) -> np.ndarray:
    """Fixed mutation variants of ``n`` children: counts proportional to the variant rates
    (largest remainder), interleaved so that every variant gets its share of the crossover
    children (the first ones) and of the copies (i mod 4 for equal rates). [n] indices."""
    p = np.asarray(probs, np.float64) / np.sum(probs)
    counts = np.floor(p * n).astype(np.int64)
    order = np.argsort(-(p * n - counts), kind="stable")
    counts[order[: n - counts.sum()]] += 1
    variant = np.empty(n, np.int64)
    given = np.zeros(len(p))
    for i in range(n):
        v = int(np.argmax((i + 1) * counts / n - given))
        variant[i] = v
        given[v] += 1
    return variant


def _needs(variant: np.ndarray) -> dict[str, np.ndarray]:
    """The children (indices) that need each random field, given their planned variants."""
    adapts = np.asarray([v.adapts for v in VARIANTS])[variant]
    genes = np.asarray([v.genes for v in VARIANTS])[variant]
    cauchy = np.asarray([v.step == "cauchy" for v in VARIANTS])[variant]
    return {
        "adapt": np.flatnonzero(adapts),  # z0, zi
        "normal": np.flatnonzero(~cauchy),  # step
        "cauchy": np.flatnonzero(cauchy),  # cauchy
        "one": np.flatnonzero(genes == "one"),  # gene
        "group": np.flatnonzero(genes == "group"),  # group
    }


def draw_planned(
    key, variant: np.ndarray, n_cross: int, n_genes: int, slots_shape, dtype=jnp.float32
) -> Noise:
    """The random numbers of one generation whose children's variants are fixed
    (:func:`plan`): each child draws only what its variant uses (:func:`expand` gives them
    the shapes of :func:`draw`)."""
    k = rng.streams(key, 11)
    t, s = slots_shape
    n = len(variant)
    need = {name: len(rows) for name, rows in _needs(variant).items()}
    return Noise(
        parent=rng.uniform(k[0], (2, n)),
        cross=rng.uniform(k[1], (2, n_cross, t, s)),
        variant=jnp.zeros((0, 1), jnp.float32),
        group=rng.uniform(k[4], (need["group"], 1)),
        gene=rng.uniform(k[5], (need["one"],)),
        z0=rng.normal(k[6], (need["adapt"], 1), dtype),
        zi=rng.normal(k[7], (need["adapt"], n_genes), dtype),
        step=rng.normal(k[8], (need["normal"], n_genes), dtype),
        cauchy=rng.cauchy(k[9], (need["cauchy"],), dtype),
        gumbel=rng.gumbel(k[10], (2 * n,), dtype),
    )


def planned_bytes(variant: np.ndarray, n_cross: int, n_genes: int, slots_shape) -> int:
    """Memory of :func:`draw_planned`'s numbers (float32)."""
    need = {name: len(rows) for name, rows in _needs(variant).items()}
    t, s = slots_shape
    n = len(variant)
    rows = need["adapt"] * (1 + n_genes) + need["normal"] * n_genes + need["cauchy"]
    return 4 * (2 * n + 2 * n_cross * t * s + need["group"] + need["one"] + rows + 2 * n)


def expand(nz: Noise, variant: np.ndarray, probs) -> Noise:
    """Planned numbers (:func:`draw_planned`) in the shapes of :func:`draw`: zeros where a
    child's variant uses none, and variant uniforms that :func:`choose` maps, under the
    rates ``probs``, to each child's planned variant."""
    n = len(variant)
    rows = {}
    for name, idx in _needs(variant).items():
        table = np.full(n, len(idx))  # the zero row past the drawn ones
        table[idx] = np.arange(len(idx))
        rows[name] = table

    def spread(a, name):
        pad = jnp.zeros((1, *a.shape[1:]), a.dtype)
        return jnp.concatenate([a, pad])[rows[name]]

    p = np.asarray(probs, np.float64)
    cdf = np.cumsum(p)
    middle = (cdf - 0.5 * p) / cdf[-1]
    return nz._replace(
        variant=jnp.asarray(middle[variant][:, None], jnp.float32),
        group=spread(nz.group, "group"),
        gene=spread(nz.gene, "one"),
        z0=spread(nz.z0, "adapt"),
        zi=spread(nz.zi, "adapt"),
        step=spread(nz.step, "normal"),
        cauchy=spread(nz.cauchy, "cauchy"),
    )


def _index(u, n: int):
    return jnp.minimum((u * n).astype(jnp.int32), n - 1)


def choose(u, probs):
    """One category per row of ``probs`` [..., K] by inverse CDF, from uniforms u [..., 1]."""
    cdf = jnp.cumsum(probs, axis=-1)
    return jnp.minimum(jnp.sum(cdf < u * cdf[..., -1:], axis=-1), probs.shape[-1] - 1)


def tournament(u, fitness):
    """Binary-tournament winners (lower fitness wins): a random choice biased to good
    individuals. u [2, n] uniforms, fitness [N] -> indices [n]."""
    a, b = _index(u, fitness.shape[0])
    return jnp.where(fitness[b] < fitness[a], b, a)


def local_tournament(u, local, slots):
    """For each child, group and slot, a parent biased to a low *local* cost at the slot's
    particle (§3.2.2 crossover). u [2, n, T, S], local [N, P], slots [T, S] (-1 = padding)
    -> [n, T, S]."""
    a, b = _index(u, local.shape[0])
    p = jnp.maximum(slots, 0)[None]
    # argmin (a reduction) materialises the outcome; a plain `where` would be fused into the
    # crossover's gathers and re-evaluated for every gene.
    second_wins = jnp.argmin(jnp.stack([local[a, p], local[b, p]]), axis=0) == 1
    return jnp.where(second_wins, b, a)


def crossover(u, genes, sigma, local, slots, gene_group):
    """Multi-parent crossover per bond type (§3.2.2).

    For each bond type, for each occurrence, for each particle at its extremity, a parent is
    picked with a bias to parents whose local cost at that particle is low; the child's genes
    of that bond type are the mean of the chosen parents' genes (mutabilities: geometric mean).
    Returns child genes and mutabilities [N, G] and the parent chosen for each group and slot
    [N, T, S] (the child's own parents, for its variant-2 bias and its success count).
    """
    parents = local_tournament(u, local, slots)  # [N, T, S]
    valid = (slots >= 0).astype(genes.dtype)  # [T, S]
    per_gene = parents[:, gene_group, :]  # [N, G, S]: the parents of each gene's bond type
    w = valid[gene_group]  # [G, S]
    gidx = jnp.arange(genes.shape[1])[None, :, None]
    norm = w.sum(axis=-1)
    child = jnp.sum(genes[per_gene, gidx] * w, axis=-1) / norm
    child_sigma = jnp.exp(jnp.sum(jnp.log(sigma)[per_gene, gidx] * w, axis=-1) / norm)
    return child, child_sigma, parents


def slot_costs(local, slots):
    """The local cost of each child's parent at each group slot's particle: local [N, P]
    (the parent's local costs, one row per child) -> [N, T, S]."""
    return local[:, jnp.maximum(slots, 0)]


def crossover_slot_costs(local, parents, slots):
    """For crossover children: at each slot, the local cost of the parent chosen *for that
    slot* at the slot's particle. local [M, P] (population), parents [N, T, S] -> [N, T, S]."""
    return local[parents, jnp.maximum(slots, 0)[None]]


def crossover_reference(cost, parents, slots):
    """The cost a crossover child must beat to count as a success: the best (lowest) global
    cost among its own parents. cost [M], parents [N, T, S] -> [N]."""
    valid = (slots >= 0)[None]
    return jnp.min(jnp.where(valid, cost[parents], jnp.inf), axis=(1, 2))


def group_bias(per_slot, slots, n_groups):
    """Probability of each bond type for variant (2): proportional to the mean local cost of
    its particles in the child's parent(s) (``per_slot`` [N, T, S], from :func:`slot_costs`
    or :func:`crossover_slot_costs`), so badly fitted parts of the body get mutated more.
    -> [N, T]."""
    valid = slots >= 0
    per_slot = jnp.where(valid[None], per_slot, 0.0)
    score = per_slot.sum(-1) / jnp.maximum(valid.sum(-1), 1)[None]
    score = jnp.where(jnp.isfinite(score), score, 0.0)
    total = score.sum(-1, keepdims=True)
    uniform = jnp.full_like(score, 1.0 / n_groups)
    return jnp.where(total > 0, score / jnp.where(total > 0, total, 1.0), uniform)


def mutate(
    noise: Noise, genes, sigma, variant, group_prob, gene_group, bounds: Bounds, sigma_floor
):
    """Apply the drawn mutation variant to each child.

    Mutabilities self-adapt log-normally before the genes move (Schwefel:
    tau' = 1/sqrt(2n), tau = 1/sqrt(2 sqrt(n))). variant [N] indexes :data:`VARIANTS`.
    """
    n, g = genes.shape
    tau_global = 1.0 / jnp.sqrt(2.0 * g)
    tau_local = 1.0 / jnp.sqrt(2.0 * jnp.sqrt(g))
    group = choose(noise.group, group_prob)  # [N]
    one_gene = _index(noise.gene, g)

    in_group = gene_group[None, :] == group[:, None]  # [N, G]
    single = jnp.arange(g)[None, :] == one_gene[:, None]
    # Per child, from the table: which genes move, whether mutabilities adapt, which step.
    # As in Schwefel's scheme the whole strategy vector self-adapts before the genes move in
    # every adapting variant: "group" and "one" restrict which genes *move*, not which
    # mutabilities adapt. (Adapting only some variants, or only the moved genes, leaves the
    # selected individuals' mutabilities near their initial size: fits stall.)
    moves = jnp.asarray([_GENES.index(m.genes) for m in VARIANTS])[variant][:, None]
    touched = jnp.where(moves == 1, in_group, jnp.where(moves == 2, single, True))
    adapt = jnp.broadcast_to(
        jnp.asarray([m.adapts for m in VARIANTS])[variant][:, None], touched.shape
    )
    cauchy_step = jnp.asarray([m.step == "cauchy" for m in VARIANTS])[variant][:, None]

    span = bounds.upper - bounds.lower
    z0, zi, step = (x.astype(genes.dtype) for x in (noise.z0, noise.zi, noise.step))
    new_sigma = jnp.where(adapt, sigma * jnp.exp(tau_global * z0 + tau_local * zi), sigma)
    new_sigma = jnp.clip(new_sigma, sigma_floor * span, span)
    cauchy = noise.cauchy.astype(genes.dtype)[:, None]
    delta = jnp.where(cauchy_step, new_sigma * cauchy, new_sigma * step)
    moved = jnp.where(touched, genes + delta, genes)
    return reflect(moved, bounds), new_sigma


def reflect(genes, bounds: Bounds):
    """Fold genes back into [lower, upper] (reflection once, then clip)."""
    lo, hi = bounds.lower, bounds.upper
    genes = jnp.where(genes < lo, 2 * lo - genes, genes)
    genes = jnp.where(genes > hi, 2 * hi - genes, genes)
    return jnp.clip(genes, lo, hi)


def _top_k(keys, k: int):
    """Indices of the k largest keys. Ranks on float32 keys: XLA's CPU top-k has a fast path
    for float32 only (float64 falls back to a full sort, ~10x slower)."""
    return jax.lax.top_k(keys.astype(jnp.float32), k)[1]


def select(gumbel, cost, n_keep: int, n_elite: int, pressure: float):
    """Survivors: the ``n_elite`` best unchanged (elitism, so the best cost never rises), the
    rest drawn at random without replacement, biased to low global cost (Gumbel top-k on
    logits ``-pressure/4 * z`` with z the standardised log cost). Non-finite costs rank below
    every finite one and are only drawn when fewer finite candidates than places exist.
    cost [M] -> indices [n_keep]."""
    cost = jnp.where(jnp.isnan(cost), jnp.inf, cost)  # NaN ranks as the worst
    # The exact best first (float32 ranking may swap near-ties), then the next best.
    best = jnp.argmin(cost)
    others = _top_k(-cost.at[best].set(jnp.inf), n_elite - 1) if n_elite > 1 else None
    elite = best[None].astype(jnp.int32)
    if others is not None:
        elite = jnp.concatenate([elite, others.astype(jnp.int32)])
    finite = jnp.isfinite(cost)
    log_cost = jnp.log(jnp.where(finite, cost, 1.0) + 1e-300)
    count = jnp.maximum(finite.sum(), 1)
    mean = jnp.sum(jnp.where(finite, log_cost, 0.0)) / count
    var = jnp.sum(jnp.where(finite, (log_cost - mean) ** 2, 0.0)) / count
    z = (log_cost - mean) / jnp.sqrt(var + 1e-12)
    logits = jnp.where(finite, -0.25 * pressure * z + gumbel.astype(cost.dtype), -1e6 + gumbel)
    logits = logits.at[elite].set(-jnp.inf)
    rest = _top_k(logits, n_keep - n_elite)
    return jnp.concatenate([elite, rest])
