"""Several seeds of one identification at once: the ES vmapped over independent runs.

Each seed's run is the same pure function of (problem, settings, seed) as a single fit; the
seeds only share the compiled code and the vector width, which is cheaper than running them
one after another on a CPU.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ..identify import es
from ..identify.cost import rms_mm
from ..identify.driver import chunk_length
from ..identify.problem import Identification
from ..runtime import float64


@dataclass
class SeedRuns:
    seeds: list[int]
    best_rms_mm: np.ndarray  # [n_seeds, generations]
    median_rms_mm: np.ndarray  # [n_seeds, generations]
    genomes: np.ndarray  # [n_seeds, G] best genome of each seed (search space)
    final_rms_mm: np.ndarray  # [n_seeds]
    failed: np.ndarray  # [n_seeds] non-finite evaluations
    seconds: float


@float64
def run_seeds(
    ident: Identification,
    settings: es.ESSettings,
    seeds: list[int],
    generations: int,
    progress: Callable[[int, int], None] | None = None,
    chunk: int = 250,
) -> SeedRuns:
    dtype = jnp.float64
    problem = ident.problem
    keys = jnp.stack([jax.random.PRNGKey(s) for s in seeds])
    split = jax.vmap(jax.random.split)(keys)
    init_keys, gen_keys = split[:, 0], split[:, 1]
    init = jax.jit(jax.vmap(partial(es.init, problem=problem, settings=settings, dtype=dtype)))
    k = chunk_length(problem, settings, chunk, runs=len(seeds))
    step = jax.jit(
        jax.vmap(lambda key, st, stop: es.run(key, st, problem, settings, k, stop), (0, 0, None))
    )
    start = time.time()
    state = init(init_keys)
    n_terms = ident.windows.n_terms
    best, median = [], []
    done = 0
    while done < generations:
        state, (rows, active) = step(gen_keys, state, generations)
        act = np.asarray(active)[0]
        best.append(np.asarray(rows.best)[:, act])
        median.append(np.asarray(rows.median)[:, act])
        done = int(np.asarray(state.generation)[0])
        if progress is not None:
            progress(done, generations)
    idx = np.asarray(jnp.argmin(state.cost, axis=1))
    genomes = np.asarray(state.genes)[np.arange(len(seeds)), idx]
    best_all = np.concatenate(best, axis=1)
    return SeedRuns(
        seeds=list(seeds),
        best_rms_mm=rms_mm(best_all, n_terms),
        median_rms_mm=rms_mm(np.concatenate(median, axis=1), n_terms),
        genomes=genomes.astype(np.float64),
        final_rms_mm=rms_mm(best_all[:, -1], n_terms),
        failed=np.asarray(state.failed_total),
        seconds=time.time() - start,
    )
