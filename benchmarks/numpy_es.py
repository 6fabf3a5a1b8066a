"""The package's ES and short-term cost, written in plain NumPy as a careful scientist would.

Same algorithm as ``activebonds.identify.search.es`` / ``operators`` (tournament parents; multi-parent
crossover per bond type biased by local cost; one of four mutation variants per child with
log-normal self-adaptation; elitist, rank-biased selection from parents + children) and the same
cost as ``activebonds.identify.costs.windows.make_cost`` (restart from the recorded state with a
backward-difference velocity, semi-implicit Euler or velocity Verlet, H steps; binary
viscoelastic and mechanical-neural bonds, gravity: a fixed vector or a free magnitude along a
fixed direction; masses, free as ratios of a total mass or not). None of these forces depends
on time, so the restart windows' times (``windows.times``) are not needed here. Random numbers come from NumPy's PCG64, so
runs are statistically, not bitwise, equal to the package's.

Everything is vectorised over the population with broadcasting on [N, S, P, D] arrays (N
individuals, S restart states, P particles, D axes, B binary bonds); there is no Python loop
over individuals, bonds or genes: the only loops are over integration steps (H x substeps).

    python benchmarks/numpy_es.py --check     # cost == package cost to 1e-9 relative
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import NamedTuple

import numpy as np

# ---------------------------------------------------------------------------------------------
# cost


def _fields(params) -> dict:
    """Masses, field and the binary bonds' parameters of a ``Params``, by name."""
    return {"mass": params.mass, "gravity": params.gravity, **params.bonds["binary"]}


class NumpyCost:
    """``cost(genomes [N, G]) -> (global [N], local [N, P])``, the package's short-term cost."""

    def __init__(self, model, windows, substeps: int = 1, method: str = "euler"):
        topo, layout = model.topology, model.layout
        if set(topo.active()) - {"binary"}:
            raise NotImplementedError("the NumPy baseline covers binary bonds and gravity only")
        if method not in ("euler", "verlet"):
            raise ValueError(method)
        self.method, self.substeps = method, int(substeps)
        self.n_genes = layout.n_genes
        self.log = layout.log
        self.gravity_direction, self.mass_rest = layout.gravity_direction, layout.mass_rest
        self.base = {f: np.asarray(v, np.float64) for f, v in _fields(layout.base).items()}
        self.index = {f: np.asarray(v) for f, v in _fields(layout.index).items()}
        n_b = topo.count("binary")
        pairs = topo.particles("binary")
        self.i, self.j = pairs[:, 0], pairs[:, 1]
        self.neural = np.asarray(topo.bonds["binary"]["neural"], bool)
        self.off = 1.0 - np.eye(n_b)
        # incidence [P, B]: +1 at the bond's first particle, -1 at its second (force on i is +T u)
        inc = np.zeros((topo.n_particles, n_b))
        inc[self.i, np.arange(n_b)] += 1.0
        inc[self.j, np.arange(n_b)] -= 1.0
        self.incidence = inc
        self.x0, self.v0 = windows.x0, windows.v0  # [S, P, D]
        self.x_prev = windows.x_prev
        self.target, self.weight = windows.target, windows.weight  # [S, H, P, D], [S, H, P]
        self.counts = windows.weight > 0
        self.dt, self.horizon = windows.dt, windows.horizon

    def decode(self, genomes):
        """[N, G] search space -> dict of parameter arrays with a leading N axis."""
        values = np.where(self.log, np.exp(genomes), genomes)
        padded = np.concatenate([values, np.zeros((len(values), 1))], axis=1)
        out = {}
        for field, base in self.base.items():
            index = self.index[field]
            if index.size == 0 or (index < 0).all():
                out[field] = base[None]
            else:
                gathered = padded[:, np.where(index >= 0, index, self.n_genes)]
                out[field] = np.where(index >= 0, gathered, base)
        if self.gravity_direction is not None:  # a free magnitude along a fixed direction
            out["gravity"] = out["gravity"] * self.gravity_direction
        if self.mass_rest is not None:  # free masses as weights of total_mass less the fixed
            free = self.index["mass"] >= 0
            w = out["mass"]
            total = np.sum(np.where(free, w, 0.0), axis=-1, keepdims=True)
            out["mass"] = np.where(free, self.mass_rest * (w / total), w)
        return out

    def force(self, p, x, v):
        """x, v [N, S, P, D] -> F [N, S, P, D]."""
        f = p["mass"][:, None, :, None] * p["gravity"][:, None, None, :]
        if self.i.size == 0:
            return np.broadcast_to(f, x.shape)
        d = x[:, :, self.j] - x[:, :, self.i]  # [N, S, B, D]
        length = np.sqrt(np.sum(d * d, axis=-1))
        u = d / length[..., None]
        rate = np.sum((v[:, :, self.j] - v[:, :, self.i]) * u, axis=-1)  # [N, S, B]
        elong = length - p["rest_length"][:, None]
        tension = p["stiffness"][:, None] * elong + p["damping"][:, None] * rate
        if self.neural.any():
            wl = np.swapaxes(p["length_weights"] * self.off, -1, -2)  # [N, B(j), B(b)]
            wr = np.swapaxes(p["rate_weights"] * self.off, -1, -2)
            drive = elong @ wl + rate @ wr  # [N, S, B]
            act = np.tanh(drive - p["threshold"][:, None])
            tension = tension + np.where(self.neural, p["gain"][:, None] * act, 0.0)
        return f + self.incidence @ (tension[..., None] * u)  # [P, B] @ [N, S, B, D]

    def step(self, p, x, v, h):
        inv_m = 1.0 / p["mass"][:, None, :, None]
        if self.method == "euler":
            v = v + h * self.force(p, x, v) * inv_m
            return x + h * v, v
        v_half = v + 0.5 * h * self.force(p, x, v) * inv_m
        x = x + h * v_half
        return x, v_half + 0.5 * h * self.force(p, x, v_half) * inv_m

    def advance(self, p, x, v):
        h = self.dt / self.substeps
        for _ in range(self.substeps):
            x, v = self.step(p, x, v, h)
        return x, v

    def start_velocity(self, p, n):
        """The velocity the integrator carries at each start (the package's
        ``physics.start_velocity``: exact for one substep, 3 fixed-point rounds otherwise)."""
        x = np.broadcast_to(self.x0, (n,) + self.x0.shape)
        xp = np.broadcast_to(self.x_prev, (n,) + self.x0.shape)
        v_b = np.broadcast_to(self.v0, (n,) + self.v0.shape)
        if self.substeps == 1 and self.method == "euler":
            return v_b
        inv_m = 1.0 / p["mass"][:, None, :, None]
        if self.substeps == 1:
            return v_b + 0.5 * self.dt * self.force(p, x, v_b) * inv_m
        n_sub = self.substeps
        lag = 0.5 * (n_sub + 1) / n_sub if self.method == "euler" else 0.5
        v = v_b - lag * self.dt * self.force(p, xp, v_b) * inv_m
        for _ in range(3):
            x_end, _ = self.advance(p, xp, v)
            v = v + (x - x_end) / self.dt
        x_end, v_end = self.advance(p, xp, v)
        residual = np.sqrt(np.sum((x - x_end) ** 2, axis=(-2, -1)))
        scale = np.sqrt(np.sum((x - xp) ** 2, axis=(-2, -1))) + 1e-12
        ok = (residual <= 1e-6 * scale)[..., None, None]
        return np.where(ok, v_end + (x - x_end) / self.dt, np.nan)

    def predict(self, p, n):
        """Predicted positions [N, S, H, P, D]."""
        x = np.broadcast_to(self.x0, (n,) + self.x0.shape)
        v = self.start_velocity(p, n)
        h = self.dt / self.substeps
        out = []
        for _ in range(self.horizon):
            for _ in range(self.substeps):
                x, v = self.step(p, x, v, h)
            out.append(x)
        return np.stack(out, axis=2)

    def __call__(self, genomes):
        genomes = np.atleast_2d(genomes)
        with np.errstate(all="ignore"):
            pred = self.predict(self.decode(genomes), len(genomes))
            err2 = np.sum((pred - self.target) ** 2, axis=-1)  # [N, S, H, P]
            local = np.sum(np.where(self.counts, err2, 0.0), axis=(1, 2))
            local = np.where(np.isfinite(local), local, np.inf)
            return local.sum(axis=-1), local


# ---------------------------------------------------------------------------------------------
# ES


class Noise(NamedTuple):
    """The random numbers of one generation (the package's ``operators.Noise``)."""

    parent: np.ndarray  # [2, N] uniforms: tournament candidates for the first parent
    cross: np.ndarray  # [2, C, T, S] uniforms: local-tournament candidates per slot
    variant: np.ndarray  # [N, 1] uniforms
    group: np.ndarray  # [N, 1] uniforms
    gene: np.ndarray  # [N] uniforms
    z0: np.ndarray  # [N, 1] normals
    zi: np.ndarray  # [N, G] normals
    step: np.ndarray  # [N, G] normals
    cauchy: np.ndarray  # [N]
    gumbel: np.ndarray  # [2N]


def _index(u, n: int):
    return np.minimum((u * n).astype(np.int64), n - 1)


def _finite_or_inf(cost, local):
    """A candidate whose simulation went non-finite costs +inf, globally and locally."""
    bad = ~np.isfinite(cost)
    local = np.where(bad[:, None] | ~np.isfinite(local), np.inf, local)
    return np.where(bad, np.inf, cost), local


def choose(u, probs):
    """One category per row of probs [..., K] by inverse CDF, from uniforms u [..., 1]."""
    cdf = np.cumsum(probs, axis=-1)
    return np.minimum(np.sum(cdf < u * cdf[..., -1:], axis=-1), probs.shape[-1] - 1)


class NumpyES:
    """The package's self-adaptive ES (same settings object: ``es.ESSettings``)."""

    def __init__(self, cost, lower, upper, gene_group, group_slots, settings, seed=0):
        self.cost = cost
        self.lo, self.hi = np.asarray(lower, float), np.asarray(upper, float)
        self.span = self.hi - self.lo
        self.gene_group = np.asarray(gene_group)
        self.slots = np.asarray(group_slots)
        self.s = settings
        self.rng = np.random.default_rng(seed)
        self.n, self.g = settings.population, len(self.lo)
        self.n_cross = int(round(settings.crossover_rate * settings.population))
        self.n_groups = self.slots.shape[0]
        self.valid = self.slots >= 0
        self.pslot = np.maximum(self.slots, 0)
        self.gene_w = self.valid[self.gene_group].astype(float)  # [G, S]: slots of g's group
        self.gene_norm = self.gene_w.sum(axis=-1)
        self.gene_cols = np.arange(self.g)[None, :, None]
        self.tau_global = 1.0 / math.sqrt(2.0 * self.g)
        self.tau_local = 1.0 / math.sqrt(2.0 * math.sqrt(self.g))

    @classmethod
    def from_identification(cls, ident, settings, seed=0, cost=None, substeps=1, method="euler"):
        cost = cost or NumpyCost(ident.model, ident.windows, substeps, method)
        p = ident.problem
        return cls(cost, p.lower, p.upper, p.gene_group, p.group_slots, settings, seed)

    def init(self):
        s = self.s
        self.genes = self.lo + self.span * self.rng.random((self.n, self.g))
        self.sigma = np.broadcast_to(s.sigma_init * self.span, self.genes.shape).copy()
        self.fit, self.local = _finite_or_inf(*self.cost(self.genes))
        self.variant_probs = np.asarray(s.variant_probs, float)
        self.generation = 0
        self.history = []
        return self

    def draw(self) -> Noise:
        n, c, g, rng = self.n, self.n_cross, self.g, self.rng
        return Noise(
            parent=rng.random((2, n)),
            cross=rng.random((2, c) + self.slots.shape),
            variant=rng.random((n, 1)),
            group=rng.random((n, 1)),
            gene=rng.random(n),
            z0=rng.standard_normal((n, 1)),
            zi=rng.standard_normal((n, g)),
            step=rng.standard_normal((n, g)),
            cauchy=rng.standard_cauchy(n),
            gumbel=rng.gumbel(size=2 * n),
        )

    def _group_bias(self, per_slot):
        """[N, T, S] (the parent's local cost at each slot's particle) -> [N, T]: probability
        of each group, proportional to its mean local cost."""
        per_slot = np.where(self.valid, per_slot, 0.0)
        score = per_slot.sum(-1) / np.maximum(self.valid.sum(-1), 1)
        score = np.where(np.isfinite(score), score, 0.0)
        total = score.sum(-1, keepdims=True)
        return np.where(total > 0, score / np.where(total > 0, total, 1.0), 1.0 / self.n_groups)

    def _crossover(self, u):
        """Children [0, C): per bond type, the mean of parents picked per extremity particle
        by a local-cost tournament (mutabilities: geometric mean)."""
        a, b = _index(u, self.n)  # [C, T, S] each
        parents = np.where(self.local[b, self.pslot] < self.local[a, self.pslot], b, a)
        pg = parents[:, self.gene_group]  # [C, G, S]: the parents of each gene's group
        child = np.sum(self.genes[pg, self.gene_cols] * self.gene_w, axis=-1) / self.gene_norm
        log_sigma = np.log(self.sigma)[pg, self.gene_cols]
        child_sigma = np.exp(np.sum(log_sigma * self.gene_w, axis=-1) / self.gene_norm)
        return child, child_sigma, parents

    def _mutate(self, nz, genes, sigma, variant, group_prob):
        g, s = self.g, self.s
        group = choose(nz.group, group_prob)
        one_gene = _index(nz.gene, g)
        v = variant[:, None]
        in_group = self.gene_group[None, :] == group[:, None]
        single = np.arange(g)[None, :] == one_gene[:, None]
        touched = np.where(v == 1, in_group, np.where(v == 3, single, True))
        adapt = np.broadcast_to(v != 2, touched.shape)
        z0, zi, step = (np.asarray(x, np.float64) for x in (nz.z0, nz.zi, nz.step))
        new_sigma = np.where(
            adapt, sigma * np.exp(self.tau_global * z0 + self.tau_local * zi), sigma
        )
        new_sigma = np.clip(new_sigma, s.sigma_floor * self.span, self.span)
        cauchy = np.asarray(nz.cauchy, np.float64)[:, None]
        delta = np.where(v == 3, new_sigma * cauchy, new_sigma * step)
        moved = np.where(touched, genes + delta, genes)
        moved = np.where(moved < self.lo, 2 * self.lo - moved, moved)
        moved = np.where(moved > self.hi, 2 * self.hi - moved, moved)
        return np.clip(moved, self.lo, self.hi), new_sigma

    def _select(self, gumbel, cost):
        """The n_elite best, then Gumbel top-k on -pressure/4 * (standardised log cost).

        As the package, rankings are taken on float32 keys (its top-k's fast path) with the
        exact best forced into the elite; stable sorts give top-k's tie order (lower index)."""
        s, n = self.s, self.n
        n_elite = s.n_elite
        cost = np.where(np.isnan(cost), np.inf, cost)
        elite = np.argsort(cost.astype(np.float32), kind="stable")[:n_elite]
        best = int(np.argmin(cost))
        if best not in elite:
            elite[-1] = best
        finite = np.isfinite(cost)
        log_cost = np.log(np.where(finite, cost, 1.0) + 1e-300)
        count = max(int(finite.sum()), 1)
        mean = np.sum(np.where(finite, log_cost, 0.0)) / count
        var = np.sum(np.where(finite, (log_cost - mean) ** 2, 0.0)) / count
        z = (log_cost - mean) / np.sqrt(var + 1e-12)
        gumbel = np.asarray(gumbel, np.float64)
        logits = np.where(finite, -0.25 * s.selection_pressure * z + gumbel, -1e6 + gumbel)
        logits[elite] = -np.inf
        rest = np.argsort(-logits.astype(np.float32), kind="stable")[: n - n_elite]
        return np.concatenate([elite, rest])

    def step(self, nz: Noise | None = None):
        s, n, c = self.s, self.n, self.n_cross
        nz = nz if nz is not None else self.draw()
        a, b = _index(nz.parent, n)
        first = np.where(self.fit[b] < self.fit[a], b, a)
        genes, sigma = self.genes[first], self.sigma[first]
        per_slot = self.local[first][:, self.pslot]  # [N, T, S]
        reference = self.fit[first]
        if c > 0:
            cross_genes, cross_sigma, parents = self._crossover(nz.cross)
            genes = np.concatenate([cross_genes, genes[c:]])
            sigma = np.concatenate([cross_sigma, sigma[c:]])
            per_slot = np.concatenate([self.local[parents, self.pslot], per_slot[c:]])
            cross_ref = np.min(np.where(self.valid, self.fit[parents], np.inf), axis=(1, 2))
            reference = np.concatenate([cross_ref, reference[c:]])

        variant = choose(nz.variant, np.broadcast_to(self.variant_probs, (n, 4)))
        group_prob = self._group_bias(per_slot)
        genes, sigma = self._mutate(nz, genes, sigma, variant, group_prob)

        cost, local = _finite_or_inf(*self.cost(genes))
        failed = int(n - np.isfinite(cost).sum())
        onehot = variant[:, None] == np.arange(4)
        trials = onehot.sum(0)
        successes = (onehot & (cost < reference)[:, None]).sum(0)

        all_cost = np.concatenate([self.fit, cost])
        self.pool_cost = all_cost  # parents + children, for the self-test's tie detection
        keep = self._select(nz.gumbel, all_cost)
        self.genes = np.concatenate([self.genes, genes])[keep]
        self.sigma = np.concatenate([self.sigma, sigma])[keep]
        self.local = np.concatenate([self.local, local])[keep]
        self.fit = all_cost[keep]
        if s.adapt_variants:
            rate = (successes + 1.0) / (trials + 2.0)
            probs = 0.9 * self.variant_probs + 0.1 * rate / rate.sum()
            probs = np.maximum(probs, 0.05)
            self.variant_probs = probs / probs.sum()
        self.generation += 1
        fin = self.fit[np.isfinite(self.fit)]
        self.history.append(
            (
                self.fit.min(),
                np.median(self.fit),
                fin.max() if fin.size else np.inf,
                failed,
                trials,
                successes,
            )
        )

    def run(self, n_generations: int):
        for _ in range(n_generations):
            self.step()
        return self

    def best(self):
        i = int(np.argmin(self.fit))
        return self.genes[i], self.fit[i], self.local[i]


# ---------------------------------------------------------------------------------------------
# self-test


def check(verbose: bool = True) -> bool:
    """Compare NumpyCost with the package's jitted, vmapped make_cost on random genomes."""
    import jax
    import jax.numpy as jnp

    sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent))
    import problems as P
    from activebonds.identify.costs.windows import make_cost
    from activebonds.identify.search.es import ESSettings

    rng = np.random.default_rng(0)
    cases = [
        P.paper_horse("standard"),
        P.paper_horse("neural"),
        P.paper_horse("neural", 60, 10),
        P.full_horse(10),
        P.mesh(),
        P.triangle(),
    ]
    ok = True
    worst_all = 0.0
    for bench in cases:
        ident = bench.ident
        for method in ("euler", "verlet"):
            substeps = 3 if method == "euler" else 2
            ref = jax.jit(jax.vmap(make_cost(ident.model, ident.windows, substeps, method)))
            mine = NumpyCost(ident.model, ident.windows, substeps, method)
            lo, hi = ident.problem.lower, ident.problem.upper
            genomes = lo + (hi - lo) * rng.random((64, len(lo)))
            # half near the file's values: with substeps, uniform genomes of the stiff problems
            # all fail the start-velocity solve (+inf), which would leave nothing to compare
            near = ident.model.layout.initial() + 0.02 * (hi - lo) * rng.normal(size=(32, len(lo)))
            genomes[32:] = np.clip(near, lo, hi)
            genomes[0] = ident.model.layout.initial()  # the file's values
            c_ref, l_ref = (np.asarray(a) for a in ref(jnp.asarray(genomes)))
            c, loc = mine(genomes)
            same_inf = np.array_equal(np.isinf(c_ref), np.isinf(c)) and np.array_equal(
                np.isinf(l_ref), np.isinf(loc)
            )
            fin = np.isfinite(c_ref) & np.isfinite(c)
            lfin = np.isfinite(l_ref) & np.isfinite(loc)
            # relative to the cost, except where the cost is rounding noise (the file's values
            # on synthetic data give ~1e-30): there relative to the typical cost of the problem
            floor = 1e-12 * np.median(c_ref[fin])
            rel = np.abs(c[fin] - c_ref[fin]) / np.maximum(np.abs(c_ref[fin]), floor)
            lrel = np.abs(loc[lfin] - l_ref[lfin]) / np.maximum(np.abs(l_ref[lfin]), floor)
            worst = max(rel.max(initial=0.0), lrel.max(initial=0.0))
            worst_all = max(worst_all, worst)
            good = same_inf and worst <= 1e-9
            ok &= good
            # every candidate +inf in both (the start-velocity solve fails for all): they
            # agree, but nothing finite was compared; said as such, not counted as a check
            label = "BAD" if not good else ("n/a" if fin.sum() == 0 else "ok ")
            if verbose:
                print(
                    f"{label} {bench.name:26s} {method:6s} finite "
                    f"{int(fin.sum()):2d}/64  max rel diff {worst:.2e}"
                    + ("  (all +inf in both: nothing finite to compare)" if label == "n/a" else "")
                )
    # the same generation: the package's random numbers fed to both, state compared
    for bench, pop in ((P.paper_horse("neural"), 64), (P.triangle(), 40), (P.full_horse(10), 24)):
        good, worst, tied = check_generations(bench, pop, 5)
        ok &= good
        if verbose:
            print(
                f"{'ok ' if good else 'BAD'} {bench.name:26s} ES, pop {pop}: 5 generations from "
                f"the package's state and random numbers, max rel diff of the next state "
                f"{worst:.1e} ({tied} tied rows: costs only)"
            )
    # the ES on its own random numbers improves the triangle, elitist
    bench = P.triangle()
    settings = ESSettings(population=100)
    es = NumpyES.from_identification(bench.ident, settings, seed=0).init()
    c0 = es.fit.min()
    t = time.perf_counter()
    es.run(300)
    dt = time.perf_counter() - t
    c1 = es.fit.min()
    improved = c1 < 1e-3 * c0 and np.all(np.diff([h[0] for h in es.history]) <= 0)
    ok &= bool(improved)
    if verbose:
        print(
            f"{'ok ' if improved else 'BAD'} NumpyES triangle pop 100: best cost {c0:.3e} -> "
            f"{c1:.3e} in 300 generations ({300 / dt:.0f} gen/s), elitist (never rises)"
        )
        print(f"{'PASSED' if ok else 'FAILED'} (worst relative cost difference {worst_all:.1e})")
    return bool(ok)


def _rel(a, b, scale=1e-300) -> float:
    """Largest |a - b| / max(|b|, scale); inf where only one side is infinite."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if not np.array_equal(np.isinf(a), np.isinf(b)):
        return np.inf
    f = np.isfinite(a)
    scale = np.broadcast_to(scale, a.shape)[f]
    return float((np.abs(a[f] - b[f]) / np.maximum(np.abs(b[f]), scale)).max(initial=0.0))


def check_generations(bench, population: int, n_generations: int) -> tuple[bool, float, int]:
    """Feed both ESs the package's random numbers (``PaperES.draw``) and the package's state,
    generation after generation: each NumPy generation must give the package's next state.

    Costs and local costs must agree everywhere. Genes and mutabilities are compared on the
    rows whose cost has no near-twin in the pool (parents + children within 1e-9 relative):
    a child whose mutation did not change its cost (a saturated neuron) ties with its parent,
    and the two costs, summed in different orders by XLA and NumPy, may then rank either way."""
    from functools import partial

    import jax
    import jax.numpy as jnp

    from activebonds.identify.search import es, evolve

    settings = bench.settings.model_copy(update={"population": population}).es()
    problem = bench.problem
    strategy = es.PaperES(problem, settings, jnp.float64)
    init_key, gen_key = evolve.keys(3)
    run = jax.jit(partial(evolve.start, strategy, problem, jnp.float64))(init_key)
    mine = NumpyES.from_identification(bench.ident, settings).init()
    one = jax.jit(partial(evolve.step, strategy, problem, jnp.float64))
    noise = jax.jit(lambda g: strategy.draw(jax.random.fold_in(gen_key, g)))
    worst, tied = 0.0, 0
    for g in range(n_generations):
        state = run.strategy
        mine.genes, mine.sigma = np.array(state.genes), np.array(state.sigma)
        mine.fit, mine.local = np.array(state.cost), np.array(state.local)
        mine.variant_probs = np.array(state.variant_probs, np.float64)
        nz = noise(jnp.int32(g))
        run, _ = one(nz, run)
        state = run.strategy
        mine.step(Noise(**{f: np.asarray(getattr(nz, f)) for f in Noise._fields}))
        worst = max(worst, _rel(mine.fit, state.cost), _rel(mine.local, state.local))
        pool = mine.pool_cost[None, :]
        near = np.abs(pool - mine.fit[:, None]) <= 1e-9 * np.abs(mine.fit[:, None])
        alone = near.sum(axis=1) <= 1  # only itself
        tied += int((~alone).sum())
        worst = max(
            worst,
            _rel(mine.genes[alone], np.asarray(state.genes)[alone], mine.span),
            _rel(mine.sigma[alone], np.asarray(state.sigma)[alone]),
        )
    return worst <= 1e-9, worst, tied


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare with the package's cost")
    args = ap.parse_args(argv)
    if args.check:
        return 0 if check() else 1
    ap.print_help()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
