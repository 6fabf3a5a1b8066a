"""Several seeds of one identification at once: the ES vmapped over independent runs.

Each seed's run is the same pure function of (problem, settings, seed) as a single fit; the
seeds only share the compiled code and the vector width, which is cheaper than running them
one after another on a CPU.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..identify.costs.windows import Display
from ..identify.problem import Identification
from ..identify.search import es
from ..identify.search.evolve import DEFAULT_CHUNK, Evolution, keys
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
    chunk: int = DEFAULT_CHUNK,
) -> SeedRuns:
    dtype = jnp.float64
    problem = ident.problem
    strategy = es.PaperES(problem, settings, dtype)
    display = Display(ident.windows.n_terms)
    loop = Evolution(
        strategy,
        problem,
        dtype,
        total=generations,
        requested=chunk,
        display=display,
        seeds=len(seeds),
    )
    split = jnp.stack([keys(s) for s in seeds])
    init_keys, gen_keys = split[:, 0], split[:, 1]
    start = time.time()
    state = loop.start(init_keys)
    best, median = [], []
    for latest, rows in loop.run(gen_keys, state, generations):
        state = latest
        best.append(rows["best_rms_mm"])
        median.append(rows["median_rms_mm"])
        if progress is not None:
            progress(int(rows["generation"][-1]), generations)
    genomes = np.stack([np.asarray(strategy.best(s)[0]) for s in _unstack(state.strategy)])
    best_all = np.concatenate(best, axis=1)
    return SeedRuns(
        seeds=list(seeds),
        best_rms_mm=best_all,
        median_rms_mm=np.concatenate(median, axis=1),
        genomes=genomes.astype(np.float64),
        final_rms_mm=best_all[:, -1],
        failed=np.asarray(state.failed_total),
        seconds=time.time() - start,
    )


def _unstack(tree):
    n = jax.tree.leaves(tree)[0].shape[0]
    return [jax.tree.map(lambda a, i=i: a[i], tree) for i in range(n)]
