"""The short-term cost and the ES operators, on small hand-built inputs.

Cost (DESIGN.md §3): backward-difference velocities, one-step (H = 1) and horizon-H
predictions restarted from the recorded state, masked gaps, local costs per particle, +inf for
a non-finite prediction. Operators (paper §3.2.2): multi-parent crossover per bond type with
a local tournament, the group bias of mutation variant (2), the four mutation variants with
log-normal self-adaptation, reflection into the bounds, and elitist biased selection.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from activebonds.identify.costs.windows import make_cost, make_windows, rms_mm
from activebonds.identify.search import operators as ops
from activebonds.model import load_model, loads_model
from activebonds.simulation import simulate
from helpers import TRIANGLE

# Compiled once per module (eager op-by-op dispatch is slow on CPU).
crossover = jax.jit(ops.crossover)
local_tournament = jax.jit(ops.local_tournament)
group_bias = jax.jit(ops.group_bias, static_argnums=2)
mutate = jax.jit(ops.mutate)
select = jax.jit(ops.select, static_argnums=(2, 3))
reflect = jax.jit(ops.reflect)

# --------------------------------------------------------------------------------------------
# Cost
# --------------------------------------------------------------------------------------------

# Particle P (mass 2) on a unary spring to the origin whose stiffness is the only gene;
# particle Q is free. With k = 0 nothing acts, so a prediction is a linear extrapolation.
SPRING_AND_FREE = """
name = "spring_and_free"
dimension = 2

[[particle]]
name = "P"
mass = 2.0

[[particle]]
name = "Q"

[[bond]]
kind = "unary"
particles = ["P"]
stiffness = { value = 0.0, min = 0.0, max = 10.0 }
damping = 0.0
anchor = [0.0, 0.0]
"""
MASS_P = 2.0


@pytest.fixture(scope="module")
def toy():
    model = loads_model(SPRING_AND_FREE)
    assert model.layout.n_genes == 1 and not model.layout.log[0]
    return model


def reference_cost(positions, mask, dt, horizon, k):
    """Independent NumPy loop: (global cost, local [P], n_terms) of the toy model."""
    n_frames, n_p, _ = positions.shape
    horizon = max(1, min(horizon, n_frames - 2))
    local = np.zeros(n_p)
    n_terms = 0
    for s in range(1, n_frames - 1, horizon):
        if not (mask[s].all() and mask[s - 1].all()):
            continue  # a missing input removes the whole restart window
        x = positions[s].copy()
        v = (positions[s] - positions[s - 1]) / dt
        for t in range(s + 1, min(s + horizon, n_frames - 1) + 1):
            acc = np.zeros_like(x)
            acc[0] = -k * x[0] / MASS_P  # semi-implicit Euler, spring on P only
            v = v + dt * acc
            x = x + dt * v
            for p in range(n_p):
                if mask[t, p]:
                    local[p] += np.sum((x[p] - positions[t, p]) ** 2)
                    n_terms += 1
    return local.sum(), local, n_terms


def toy_cost(model, positions, mask, dt, horizon, k):
    windows = make_windows(positions, mask, dt, horizon)
    cost, local = jax.jit(make_cost(model, windows))(jnp.array([k], dtype=jnp.float64))
    return windows, float(cost), np.asarray(local)


# Four frames of two particles (2D), dt = 0.5 s.
FOUR_P = [[0.0, 0.0], [1.0, 0.0], [3.0, 1.0], [4.0, 4.0]]
FOUR_Q = [[0.0, 1.0], [0.0, 1.0], [0.0, 2.0], [1.0, 2.0]]


def four_frames():
    return np.stack([np.array(FOUR_P), np.array(FOUR_Q)], axis=1), np.ones((4, 2), bool)


def test_velocities_are_backward_differences_on_four_frames(toy):
    x, mask = four_frames()
    w = make_windows(x, mask, dt=0.5, horizon=1)
    # starts s = 1, 2; v_s = (x_s - x_{s-1}) / dt by hand
    np.testing.assert_array_equal(w.x0, [[[1, 0], [0, 1]], [[3, 1], [0, 2]]])
    np.testing.assert_array_equal(w.v0, [[[2, 0], [0, 0]], [[4, 2], [0, 2]]])
    np.testing.assert_array_equal(w.target[:, 0], [[[3, 1], [0, 2]], [[4, 4], [1, 2]]])
    assert w.n_terms == 4 and w.horizon == 1

    # k = 0: prediction x_s + dt v_s = 2 x_s - x_{s-1}; squared errors by hand:
    # s=1: P (2,0) vs (3,1) -> 2, Q (0,1) vs (0,2) -> 1; s=2: P (5,2) vs (4,4) -> 5,
    # Q (0,3) vs (1,2) -> 2.
    _, cost, local = toy_cost(toy, x, mask, 0.5, 1, 0.0)
    assert cost == pytest.approx(10.0, abs=1e-12)
    np.testing.assert_allclose(local, [7.0, 3.0], atol=1e-12)
    assert float(rms_mm(cost, 4)) == pytest.approx(np.sqrt(10.0 / 4) * 1000)

    # k = 1 (P's mass 2): v' = v - dt k x / m, x' = x + dt v'.
    # s=1: v' = (1.75, 0), x' = (1.875, 0) -> 1.125^2 + 1 = 2.265625
    # s=2: v' = (3.25, 1.75), x' = (4.625, 1.875) -> 0.625^2 + 2.125^2 = 4.90625
    _, cost, local = toy_cost(toy, x, mask, 0.5, 1, 1.0)
    np.testing.assert_allclose(local, [2.265625 + 4.90625, 3.0], atol=1e-12)
    assert cost == pytest.approx(10.171875, abs=1e-12)


def test_true_model_has_zero_cost_and_perturbations_a_positive_one():
    """Data simulated by semi-implicit Euler with the same dt and one substep are reproduced
    exactly by the true parameters, for every horizon."""
    model = load_model(TRIANGLE)
    traj = simulate(model, n_frames=40, rate=60.0)
    truth = jnp.asarray(model.layout.initial())
    for horizon in (1, 3, 8):
        windows = make_windows(traj.positions, traj.mask, traj.dt, horizon)
        cost_fn = jax.jit(make_cost(model, windows))
        cost, local = cost_fn(truth)
        assert float(cost) < 1e-20, (horizon, float(cost))
        assert np.all(np.asarray(local) >= 0)
        for g, gene in enumerate(model.layout.genes):
            # a 1 % change of any one parameter (search space: log or linear)
            step = np.log(1.01) if gene.log else 0.01 * gene.value
            perturbed = truth.at[g].add(step)
            c, loc = cost_fn(perturbed)
            assert float(c) > 1e-12, (horizon, gene.name, float(c))
            # local costs sum to the global cost
            assert float(jnp.sum(loc)) == pytest.approx(float(c), rel=1e-12)


def test_masked_gaps_one_step(toy):
    """A missing target contributes nothing; a missing input frame removes its window."""
    rng = np.random.default_rng(1)
    x = rng.normal(size=(6, 2, 2))
    mask = np.ones((6, 2), bool)
    mask[5, 0] = False  # P missing at frame 5: only the target of start 4
    mask[2, 1] = False  # Q missing at frame 2: target of start 1, input of starts 2 and 3
    x[~mask] = np.nan
    windows, cost, local = toy_cost(toy, x, mask, 0.1, 1, 3.0)
    # starts 1..4: s=1 -> P only; s=2, s=3 -> removed (input); s=4 -> Q only
    assert windows.n_terms == 2
    np.testing.assert_array_equal(windows.weight[:, 0], [[1, 0], [0, 0], [0, 0], [0, 1]])
    ref_cost, ref_local, ref_terms = reference_cost(x, mask, 0.1, 1, 3.0)
    assert ref_terms == 2
    assert np.isfinite(cost)
    assert cost == pytest.approx(ref_cost, rel=1e-12)
    np.testing.assert_allclose(local, ref_local, rtol=1e-12)
    # whatever the missing samples hold, nothing changes
    x2 = x.copy()
    x2[~mask] = 1e6
    _, cost2, _ = toy_cost(toy, x2, mask, 0.1, 1, 3.0)
    assert cost2 == cost


def test_masked_gaps_with_horizon(toy):
    rng = np.random.default_rng(2)
    x = rng.normal(size=(10, 2, 2))
    mask = np.ones((10, 2), bool)
    mask[3, 1] = False  # target (k=2) of start 1; input of start 4 -> its 3x2 terms go
    x[~mask] = np.nan
    windows, cost, local = toy_cost(toy, x, mask, 0.05, 3, 0.5)
    # starts 1, 4, 7 with 3, 3, 2 predicted frames: 16 terms without gaps
    assert windows.weight.shape == (3, 3, 2)
    assert windows.n_terms == 16 - 1 - 6
    ref_cost, ref_local, ref_terms = reference_cost(x, mask, 0.05, 3, 0.5)
    assert ref_terms == windows.n_terms
    assert cost == pytest.approx(ref_cost, rel=1e-12)
    np.testing.assert_allclose(local, ref_local, rtol=1e-12)


@pytest.mark.parametrize(
    ("horizon", "n_starts", "frames_per_start"),
    [(1, 8, [1] * 8), (3, 3, [3, 3, 2]), (8, 1, [8]), (50, 1, [8])],
)
def test_horizon_starts_and_terms(toy, horizon, n_starts, frames_per_start):
    """F = 10 frames: starts 1, 1+H, ...; every frame 2..9 is predicted exactly once."""
    rng = np.random.default_rng(3)
    x = rng.normal(size=(10, 2, 2))
    mask = np.ones((10, 2), bool)
    windows, cost, local = toy_cost(toy, x, mask, 0.1, horizon, 2.0)
    assert windows.x0.shape[0] == n_starts
    assert windows.horizon == min(horizon, 8)
    np.testing.assert_array_equal(windows.weight[:, :, 0].sum(axis=1), frames_per_start)
    assert windows.n_terms == 2 * 8
    np.testing.assert_array_equal(windows.x0, x[1 :: min(horizon, 8)][:n_starts])
    ref_cost, ref_local, ref_terms = reference_cost(x, mask, 0.1, horizon, 2.0)
    assert ref_terms == windows.n_terms
    assert cost == pytest.approx(ref_cost, rel=1e-12)
    np.testing.assert_allclose(local, ref_local, rtol=1e-12)
    assert local.sum() == pytest.approx(cost, rel=1e-14)


def test_non_finite_prediction_costs_inf():
    model = load_model(TRIANGLE)
    traj = simulate(model, n_frames=20, rate=60.0)
    genome = jnp.asarray(model.layout.initial())
    stiff = [g for g, gene in enumerate(model.layout.genes) if gene.name.endswith("stiffness")]
    assert model.layout.log[stiff[0]]
    one_step = jax.jit(make_cost(model, make_windows(traj.positions, traj.mask, traj.dt, 1)))
    free_run = jax.jit(make_cost(model, make_windows(traj.positions, traj.mask, traj.dt, 10)))
    cases = [
        (one_step, genome.at[stiff[0]].set(1000.0)),  # exp(1000) = inf stiffness
        (one_step, genome.at[0].set(jnp.nan)),
        (free_run, genome.at[stiff[1]].set(300.0)),  # finite but blows up within 10 steps
    ]
    for cost_fn, g in cases:
        cost, local = cost_fn(g)
        assert float(cost) == np.inf  # +inf, never NaN
        assert np.all(np.isposinf(np.asarray(local)) | np.isfinite(np.asarray(local)))
        assert np.isposinf(np.asarray(local)).any()


# --------------------------------------------------------------------------------------------
# Crossover and the local tournament
# --------------------------------------------------------------------------------------------


def pick(indices, n):
    """Uniforms that make the tournaments draw exactly these candidate ``indices`` of n."""
    return jnp.asarray((np.asarray(indices, dtype=np.float64) + 0.5) / n, jnp.float32)


# 4 parents, 4 particles; group 0 = bond (0, 1), group 1 = bond (2, 3), group 2 = a
# one-particle group (3) padded with -1. Genes: 2 + 3 + 1.
SLOTS = np.array([[0, 1], [2, 3], [3, -1]], dtype=np.int32)
GENE_GROUP = np.array([0, 0, 1, 1, 1, 2], dtype=np.int32)
LOCAL = np.array(
    [
        [0.1, 5.0, 3.0, 2.0],
        [4.0, 0.2, 1.0, 7.0],
        [2.0, 3.0, 0.3, 9.0],
        [9.0, 1.0, 8.0, 0.4],
    ]
)
GENES = np.array([[10.0 * (i + 1) + j for j in range(6)] for i in range(4)])
SIGMA = np.array([[0.1 * 2.0**i * (1 + j) for j in range(6)] for i in range(4)])


def crossover_reference(pairs):
    """Winners by hand (lower local cost at the slot's particle; a tie keeps the first) and
    the child = mean over the group's used slots of the winners' genes."""
    n = pairs.shape[1]
    child = np.zeros((n, GENES.shape[1]))
    child_sigma = np.zeros_like(child)
    for c in range(n):
        for g, t in enumerate(GENE_GROUP):
            winners = []
            for s, p in enumerate(SLOTS[t]):
                if p < 0:
                    continue
                a, b = pairs[0, c, t, s], pairs[1, c, t, s]
                winners.append(b if LOCAL[b, p] < LOCAL[a, p] else a)
            child[c, g] = np.mean(GENES[winners, g])
            child_sigma[c, g] = np.exp(np.mean(np.log(SIGMA[winners, g])))
    return child, child_sigma


def run_crossover(pairs):
    return crossover(
        pick(pairs, 4),
        jnp.asarray(GENES),
        jnp.asarray(SIGMA),
        jnp.asarray(LOCAL),
        jnp.asarray(SLOTS),
        jnp.asarray(GENE_GROUP),
    )


def test_crossover_forced_tournament_averages_winners_per_group():
    # One child; pairs[candidate, child, group, slot].
    pairs = np.zeros((2, 1, 3, 2), dtype=int)
    pairs[:, 0, 0, 0] = (1, 0)  # particle 0: parent 0 (0.1) beats parent 1 (4.0)
    pairs[:, 0, 0, 1] = (0, 3)  # particle 1: parent 3 (1.0) beats parent 0 (5.0)
    pairs[:, 0, 1, 0] = (3, 2)  # particle 2: parent 2 (0.3) beats parent 3 (8.0)
    pairs[:, 0, 1, 1] = (1, 2)  # particle 3: parent 1 (7.0) beats parent 2 (9.0)
    pairs[:, 0, 2, 0] = (0, 3)  # particle 3: parent 3 (0.4) beats parent 0 (2.0)
    pairs[:, 0, 2, 1] = (1, 1)  # padding: must not count
    child, child_sigma, parents = run_crossover(pairs)
    child, child_sigma = np.asarray(child)[0], np.asarray(child_sigma)[0]
    # the parents returned are the winners per slot (the padding slot as drawn)
    assert np.asarray(parents)[0, :, 0].tolist() == [0, 2, 3]
    assert np.asarray(parents)[0, :2, 1].tolist() == [3, 1]
    # group 0 from parents {0, 3}, group 1 from parents {2, 1}, group 2 from parent 3 only
    np.testing.assert_allclose(child[:2], (GENES[0, :2] + GENES[3, :2]) / 2, rtol=1e-6)
    np.testing.assert_allclose(child[2:5], (GENES[2, 2:5] + GENES[1, 2:5]) / 2, rtol=1e-6)
    np.testing.assert_allclose(child[5], GENES[3, 5], rtol=1e-6)
    np.testing.assert_allclose(child[:2], [25.0, 26.0])
    np.testing.assert_allclose(child[2:5], [27.0, 28.0, 29.0])
    np.testing.assert_allclose(child[5], 45.0)
    # mutabilities: geometric mean of the same parents
    np.testing.assert_allclose(child_sigma[:2], np.sqrt(SIGMA[0, :2] * SIGMA[3, :2]), rtol=1e-6)
    np.testing.assert_allclose(child_sigma[5], SIGMA[3, 5], rtol=1e-6)


def test_crossover_matches_hand_reference_for_random_pairs():
    rng = np.random.default_rng(4)
    pairs = rng.integers(0, 4, size=(2, 64, 3, 2))
    child, child_sigma, _ = run_crossover(pairs)
    ref, ref_sigma = crossover_reference(pairs)
    np.testing.assert_allclose(np.asarray(child), ref, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(child_sigma), ref_sigma, rtol=1e-6)
    # children mix parents: genes of different groups from different parents
    mixed = [c for c in range(64) if not any(np.allclose(ref[c], GENES[i]) for i in range(4))]
    assert len(mixed) > 32


def test_local_tournament_bias_follows_the_slot_particle():
    n = 101
    rng = np.random.default_rng(5)
    cost0 = rng.permutation(n).astype(float) + 0.5  # distinct
    local = np.stack([cost0, cost0.max() + 1 - cost0], axis=1)  # particle 1: reversed ranks
    slots = np.array([[0, 1], [1, 0]], dtype=np.int32)
    u = jax.random.uniform(jax.random.PRNGKey(0), (2, 400, 2, 2))
    winners = np.asarray(local_tournament(u, jnp.asarray(local), jnp.asarray(slots)))
    assert winners.shape == (400, 2, 2)
    median = np.median(local, axis=0)
    for t in range(2):
        for s in range(2):
            p = slots[t, s]
            better = local[winners[:, t, s], p] < median[p]
            # binary tournament: P(better than the median) = 1 - (51/101)^2 = 0.745
            assert better.mean() > 0.70, (t, s, better.mean())
            other = local[winners[:, t, s], 1 - p] < median[1 - p]
            assert other.mean() < 0.30  # the bias is local, not global
    # the first candidate alone (no tournament) is unbiased
    first = np.minimum((np.asarray(u[0]) * n).astype(int), n - 1)
    assert 0.42 < (local[first[:, 0, 0], 0] < median[0]).mean() < 0.58
    # the winner is never worse than either candidate
    cand = np.minimum((np.asarray(u) * n).astype(int), n - 1)
    for t in range(2):
        for s in range(2):
            p = slots[t, s]
            w = local[winners[:, t, s], p]
            assert np.all(w <= local[cand[0, :, t, s], p])
            assert np.all(w <= local[cand[1, :, t, s], p])


def test_group_bias_prefers_badly_fitted_groups():
    local = jnp.array([[1.0, 2.0, 3.0, 10.0], [0.0, 0.0, 0.0, 0.0], [5.0, 5.0, 1.0, 1.0]])
    per_slot = ops.slot_costs(local, jnp.asarray(SLOTS))
    prob = np.asarray(group_bias(per_slot, jnp.asarray(SLOTS), 3))
    # mean local cost of each group's particles: (1+2)/2, (3+10)/2, 10 -> /18
    np.testing.assert_allclose(prob[0], np.array([1.5, 6.5, 10.0]) / 18.0, rtol=1e-12)
    np.testing.assert_allclose(prob[1], [1 / 3] * 3)  # nothing to prefer: uniform
    np.testing.assert_allclose(prob[2], np.array([5.0, 1.0, 1.0]) / 7.0, rtol=1e-12)
    np.testing.assert_allclose(prob.sum(axis=1), 1.0)


# --------------------------------------------------------------------------------------------
# Mutation
# --------------------------------------------------------------------------------------------

N_CHILD = 4000
BOUNDS = ops.Bounds(jnp.zeros(6), jnp.full(6, 10.0))


def noise(seed, n=N_CHILD, n_genes=6):
    """The random numbers ``mutate`` reads, drawn here with jax.random (fields of
    :class:`~activebonds.identify.search.operators.Noise` it does not read are left empty)."""
    k = jax.random.split(jax.random.PRNGKey(seed), 6)
    f64 = jnp.float64
    fields = {
        "group": jax.random.uniform(k[0], (n, 1), f64),
        "gene": jax.random.uniform(k[1], (n,), f64),
        "z0": jax.random.normal(k[2], (n, 1), f64),
        "zi": jax.random.normal(k[3], (n, n_genes), f64),
        "step": jax.random.normal(k[4], (n, n_genes), f64),
        "cauchy": jax.random.cauchy(k[5], (n,), f64),
    }
    return ops.Noise(**{name: fields.get(name) for name in ops.Noise._fields})


def run_mutate(variant, genes=None, sigma=None, group_prob=None, seed=0, bounds=BOUNDS):
    n = N_CHILD
    genes = jnp.full((n, 6), 5.0) if genes is None else genes
    sigma = jnp.full((n, 6), 0.05) if sigma is None else sigma
    if group_prob is None:
        group_prob = jnp.full((n, 3), 1 / 3)
    group_prob = jnp.broadcast_to(jnp.asarray(group_prob, jnp.float64), (n, 3))
    new_genes, new_sigma = mutate(
        noise(seed),
        genes,
        sigma,
        jnp.full((n,), variant, jnp.int32),
        group_prob,
        jnp.asarray(GENE_GROUP),
        bounds,
        1e-9,
    )
    return (np.asarray(genes), np.asarray(sigma), np.asarray(new_genes), np.asarray(new_sigma))


def test_variant_1_moves_every_gene_and_adapts_every_mutability():
    genes, sigma, new_genes, new_sigma = run_mutate(0)
    assert np.all(new_genes != genes)
    assert np.all(new_sigma != sigma)


def test_variant_2_moves_only_the_chosen_group():
    groups = [np.flatnonzero(GENE_GROUP == t) for t in range(3)]
    # forced to group 1
    genes, sigma, new_genes, new_sigma = run_mutate(1, group_prob=[0.0, 1.0, 0.0])
    changed = new_genes != genes
    assert np.all(changed[:, groups[1]]) and not changed[:, np.r_[groups[0], groups[2]]].any()
    assert np.all(new_sigma != sigma)  # the whole strategy vector self-adapts
    # drawn with the given probabilities; always exactly one whole group
    prob = np.array([0.2, 0.3, 0.5])
    genes, sigma, new_genes, new_sigma = run_mutate(1, group_prob=prob, seed=1)
    changed = new_genes != genes
    chosen = np.array([[changed[c, groups[t]].all() for t in range(3)] for c in range(N_CHILD)])
    assert np.all(chosen.sum(axis=1) == 1)
    for t in range(3):
        assert np.array_equal(
            changed[:, groups[t]], np.repeat(chosen[:, t : t + 1], len(groups[t]), 1)
        )
    np.testing.assert_allclose(chosen.mean(axis=0), prob, atol=0.03)


def test_variant_3_keeps_mutabilities():
    genes, sigma, new_genes, new_sigma = run_mutate(2)
    assert np.array_equal(new_sigma, sigma)
    assert np.all(new_genes != genes)


def test_variant_4_moves_exactly_one_gene_with_a_cauchy_step():
    genes, sigma, new_genes, new_sigma = run_mutate(3)
    changed = new_genes != genes
    assert np.all(changed.sum(axis=1) == 1)
    # self-adaptation: every mutability adapts, though one gene moves
    assert np.all(new_sigma != sigma)
    np.testing.assert_allclose(changed.mean(axis=0), 1 / 6, atol=0.03)  # uniform gene
    # heavy tail: |step| / sigma' has median 1 (Cauchy), not 0.674 (normal)
    ratio = np.abs(new_genes - genes)[changed] / new_sigma[changed]
    assert 0.9 < np.median(ratio) < 1.1


@pytest.mark.parametrize("variant", [0, 1, 3])
def test_every_mutating_variant_but_the_frozen_one_adapts(variant):
    """Self-adaptation needs every variant but the frozen one (3) to adapt the whole strategy
    vector; otherwise the selected individuals' mutabilities stay near their initial size
    and fits stall (the audit: 1.5e-3 mm where 1e-9 mm is reachable)."""
    genes, sigma, new_genes, new_sigma = run_mutate(variant, group_prob=[0.0, 1.0, 0.0])
    assert (new_genes != genes).any(axis=1).all()
    assert np.all(new_sigma != sigma)


def test_self_adaptation_is_log_normal_and_precedes_the_step():
    g = 16
    n = N_CHILD
    genes = jnp.full((n, g), 5.0)
    sigma = jnp.full((n, g), 1e-3)
    bounds = ops.Bounds(jnp.zeros(g), jnp.full(g, 10.0))
    new_genes, new_sigma = mutate(
        noise(3, n, g),
        genes,
        sigma,
        jnp.zeros((n,), jnp.int32),
        jnp.full((n, 3), 1 / 3),
        jnp.asarray(np.arange(g) % 3, jnp.int32),
        bounds,
        1e-9,
    )
    log_ratio = np.log(np.asarray(new_sigma) / 1e-3)
    tau_global, tau_local = 1 / np.sqrt(2 * g), 1 / np.sqrt(2 * np.sqrt(g))
    assert abs(log_ratio.mean()) < 0.02
    assert log_ratio.std() == pytest.approx(np.hypot(tau_global, tau_local), rel=0.05)
    # the shared (global) factor: covariance of two genes of one child = tau'^2
    cov = np.mean(
        (log_ratio[:, 0] - log_ratio[:, 0].mean()) * (log_ratio[:, 1] - log_ratio[:, 1].mean())
    )
    assert cov == pytest.approx(tau_global**2, abs=0.01)
    # steps are drawn with the *new* mutabilities: (x' - x) / sigma' is standard normal
    z = (np.asarray(new_genes) - 5.0) / np.asarray(new_sigma)
    assert z.std() == pytest.approx(1.0, rel=0.03)
    z_old = (np.asarray(new_genes) - 5.0) / 1e-3
    assert z_old.std() > 1.1


@pytest.mark.parametrize("variant", [0, 1, 2, 3])
def test_mutation_stays_within_bounds(variant):
    rng = np.random.default_rng(6)
    lo = np.array([0.0, -1.0, 2.0, -5.0, 0.0, 100.0])
    hi = np.array([1.0, 1.0, 3.0, 5.0, 1e-3, 101.0])
    start = lo + (hi - lo) * rng.choice([0.0, 1e-6, 0.5, 1 - 1e-6, 1.0], size=(N_CHILD, 6))
    bounds = ops.Bounds(jnp.asarray(lo), jnp.asarray(hi))
    sigma = jnp.asarray(np.broadcast_to(hi - lo, (N_CHILD, 6)) * 0.7)
    _, _, new_genes, new_sigma = run_mutate(variant, jnp.asarray(start), sigma, bounds=bounds)
    assert np.all(new_genes >= lo) and np.all(new_genes <= hi)
    assert np.all(new_sigma <= (hi - lo) * (1 + 1e-12))
    assert np.all(new_sigma >= 1e-9 * (hi - lo) * (1 - 1e-12))


def test_reflect_by_hand():
    bounds = ops.Bounds(jnp.zeros(5), jnp.ones(5))
    out = reflect(jnp.array([-0.2, 1.3, 5.0, 0.4, -7.0]), bounds)
    np.testing.assert_allclose(np.asarray(out), [0.2, 0.7, 0.0, 0.4, 0.0], atol=1e-15)


# --------------------------------------------------------------------------------------------
# Selection
# --------------------------------------------------------------------------------------------


def gumbel(seed, m):
    return jax.random.gumbel(jax.random.PRNGKey(seed), (m,), jnp.float64)


def test_select_keeps_the_elite_unchanged_and_the_size():
    rng = np.random.default_rng(7)
    cost = jnp.asarray(rng.lognormal(0.0, 3.0, size=40))
    order = np.argsort(np.asarray(cost))
    for seed in range(50):
        keep = np.asarray(select(gumbel(seed, 40), cost, 20, 2, 4.0))
        assert keep.shape == (20,)
        assert len(set(keep.tolist())) == 20  # without replacement
        np.testing.assert_array_equal(keep[:2], order[:2])


def test_select_never_takes_a_non_finite_candidate_while_finite_ones_remain():
    rng = np.random.default_rng(8)
    cost = rng.lognormal(0.0, 1.0, size=40)
    bad = rng.choice(40, size=15, replace=False)
    cost[bad[:10]] = np.inf
    cost[bad[10:]] = np.nan
    for seed in range(200):
        keep = np.asarray(select(gumbel(seed, 40), jnp.asarray(cost), 20, 2, 4.0))
        assert np.all(np.isfinite(cost[keep]))
    # fewer finite candidates than places: every finite one survives, the rest is filled
    few = np.full(40, np.inf)
    few[:8] = rng.lognormal(size=8)
    keep = np.asarray(select(gumbel(0, 40), jnp.asarray(few), 20, 2, 4.0))
    assert set(range(8)) <= set(keep.tolist()) and len(set(keep.tolist())) == 20


def test_select_random_part_favours_good_candidates():
    m, n_keep, n_elite = 40, 20, 2
    cost = jnp.asarray(np.geomspace(1e-3, 1e3, m))  # candidate i has rank i
    counts = np.zeros(m)
    uniform = np.zeros(m)
    for seed in range(300):
        counts[np.asarray(select(gumbel(seed, m), cost, n_keep, n_elite, 4.0))] += 1
        uniform[np.asarray(select(gumbel(seed, m), cost, n_keep, n_elite, 0.0))] += 1
    assert np.all(counts[:n_elite] == 300) and np.all(uniform[:n_elite] == 300)
    rest = counts[n_elite:] / 300
    # the better half of the non-elite is drawn far more often than the worse half
    assert rest[:19].mean() > 0.65 and rest[19:].mean() < 0.32
    assert rest[:5].mean() > 0.8 and rest[-5:].mean() < 0.2
    assert np.all(np.diff(np.convolve(rest, np.ones(5) / 5, "valid")) < 0.02)  # monotone trend
    # without pressure the draw is uniform: 18 of 38 places
    np.testing.assert_allclose(uniform[n_elite:] / 300, 18 / 38, atol=0.1)


# --------------------------------------------------------------------------------------------
# A crossover child is judged against its own parents
# --------------------------------------------------------------------------------------------


def test_crossover_children_refer_to_their_own_parents():
    """Individual 0 wins every global tournament (the copy parent) but loses every local one,
    so the crossover children are made from individuals 1 and 2 only. Their success count and
    variant-2 bias must use those parents, not the unrelated tournament winner."""
    from activebonds.identify.search import es, evolve

    n, g = 4, 2
    # adapt_variants: each child draws its variant from the noise below (with fixed rates the
    # variants are planned, i mod 4, and each child draws only the numbers its variant uses)
    settings = es.ESSettings(
        population=n, crossover_rate=1.0, elite_fraction=0.25, adapt_variants=True
    )
    slots = np.array([[0, 1]], dtype=np.int32)
    problem = es.Problem(
        evaluate=lambda x: (jnp.sum(x), jnp.stack([x[0], x[1]])),
        lower=np.zeros(g),
        upper=np.full(g, 10.0),
        gene_group=np.zeros(g, np.int32),
        group_slots=slots,
    )
    state = es.ESState(
        genes=jnp.array([[1.0, 1.0], [5.0, 5.0], [5.0, 5.0], [5.0, 5.0]]),
        sigma=jnp.ones((n, g)),
        cost=jnp.array([2.0, 10.0, 10.0, 10.0]),
        local=jnp.array([[100.0, 100.0], [1.0, 1.0], [1.0, 1.0], [1.0, 1.0]]),
        variant_probs=jnp.full(4, 0.25),
    )
    f = jnp.float64
    nz = ops.Noise(
        parent=jnp.full((2, n), 0.1, f),  # both candidates: individual 0
        cross=jnp.stack([jnp.full((n, 1, 2), 0.3, f), jnp.full((n, 1, 2), 0.6, f)]),  # 1 vs 2
        variant=jnp.full((n, 1), 0.1, f),  # variant (1): all genes
        group=jnp.full((n, 1), 0.5, f),
        gene=jnp.full((n,), 0.5, f),
        z0=jnp.zeros((n, 1), f),
        zi=jnp.zeros((n, g), f),
        step=jnp.full((n, g), -1.0, f),  # every child moves from (5, 5) to (4, 4): cost 8
        cauchy=jnp.zeros((n,), f),
        gumbel=jnp.zeros((2 * n,), f),
    )
    strategy = es.PaperES(problem, settings)
    run = evolve.Run(state, jnp.asarray(0, jnp.int32), jnp.asarray(0, jnp.int32))
    _, row = jax.jit(lambda nz, s: evolve.step(strategy, problem, None, nz, s))(nz, run)
    assert int(row["trials"][0]) == n
    # cost 8 beats its parents (10) though not the tournament winner (2): all successes
    assert int(row["successes"][0]) == n
    # the per-slot costs a crossover child's variant-2 bias reads are its parents' (1.0)
    parents = jnp.array([[[1, 2]]])
    per_slot = ops.crossover_slot_costs(state.local, parents, jnp.asarray(slots))
    np.testing.assert_array_equal(np.asarray(per_slot), [[[1.0, 1.0]]])
    assert float(ops.crossover_reference(state.cost, parents, jnp.asarray(slots))[0]) == 10.0


# --------------------------------------------------------------------------------------------
# Planned variants: counts proportional to the rates, and only the numbers each child uses
# --------------------------------------------------------------------------------------------


def test_planned_variants_have_proportional_interleaved_counts():
    assert list(ops.plan(8, (0.25, 0.25, 0.25, 0.25))) == [0, 1, 2, 3, 0, 1, 2, 3]
    variant = ops.plan(500, (0.4, 0.3, 0.2, 0.1))
    assert list(np.bincount(variant, minlength=4)) == [200, 150, 100, 50]
    # every variant gets its share of the first half (the crossover children) too
    assert list(np.bincount(variant[:250], minlength=4)) == [100, 75, 50, 25]
    odd = ops.plan(7, (0.5, 0.0, 0.25, 0.25))
    assert np.bincount(odd, minlength=4)[1] == 0 and len(odd) == 7


def test_planned_numbers_expand_to_each_childs_variant_and_needs():
    n, g = 12, 5
    variant = ops.plan(n, (0.25, 0.25, 0.25, 0.25))
    key = jax.random.PRNGKey(4)
    # compiled, as the ES draws them (op by op this test compiled some 240 small programs)
    nz = jax.jit(lambda k: ops.draw_planned(k, variant, 6, g, (2, 2)))(key)
    # the frozen variant (2) adapts nothing, the jump (3) takes no normal step
    assert nz.zi.shape == (9, g) and nz.step.shape == (9, g) and nz.cauchy.shape == (3,)
    assert ops.planned_bytes(variant, 6, g, (2, 2)) == sum(a.size * 4 for a in nz)
    full = ops.expand(nz, variant, (0.25, 0.25, 0.25, 0.25))
    chosen = ops.choose(full.variant, jnp.full((n, 4), 0.25))
    np.testing.assert_array_equal(np.asarray(chosen), variant)
    zi, step, cauchy = (np.asarray(a) for a in (full.zi, full.step, full.cauchy))
    assert np.all(zi[variant == 2] == 0) and np.all(zi[variant != 2] != 0)
    assert np.all(step[variant == 3] == 0) and np.all(step[variant != 3] != 0)
    assert np.all(cauchy[variant != 3] == 0) and np.all(cauchy[variant == 3] != 0)
    # the drawn rows land on the children that need them, in order
    np.testing.assert_array_equal(zi[variant != 2], np.asarray(nz.zi))
    # and unequal rates still choose the planned variants
    probs = (0.4, 0.3, 0.2, 0.1)
    uneven = ops.plan(n, probs)
    drawn = jax.jit(lambda k: ops.draw_planned(k, uneven, 6, g, (2, 2)))(key)
    full = ops.expand(drawn, uneven, probs)
    chosen = ops.choose(full.variant, jnp.broadcast_to(jnp.asarray(probs), (n, 4)))
    np.testing.assert_array_equal(np.asarray(chosen), uneven)
