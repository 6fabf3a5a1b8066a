"""Chunks sized by time: the lengths the loop picks, and results that do not depend on them."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from activebonds.identify.costs.windows import Display
from activebonds.identify.driver import fit
from activebonds.identify.problem import identification
from activebonds.identify.search import evolve, strategies
from activebonds.identify.search.evolve import Chunking
from activebonds.identify.settings import FitSettings
from activebonds.model import load_model
from activebonds.simulation import simulate
from helpers import TRIANGLE

pytestmark = pytest.mark.timeout(300)


def test_the_first_chunk_follows_the_estimate_and_never_passes_the_end():
    c = Chunking(limit=250, seconds=1.0)
    assert c.next(1000, ()) == 16  # nothing known yet
    c.estimate = 0.025  # 25 ms a generation: 40 a second
    assert c.next(1000, ()) == 40
    assert c.next(10, ()) == 10  # a 10-generation fit is one chunk of 10
    c.estimate = 1e-5
    assert c.next(10_000, ()) == 250  # at most the limit


def test_compiled_lengths_are_reused_unless_far_from_the_target():
    c = Chunking(limit=250, seconds=1.0)
    c.generation, c.compile = 0.025, 3.0  # target 40
    assert c.next(1000, (16,)) == 16  # within 4x of the target: no second compilation
    assert c.next(10_000, (5,)) == 40  # too short a chunk for a long run: compile the target
    assert c.next(1000, (5,)) == 5  # 25 s left, under 10 compilations: not worth one
    # the tail: 6 generations left, 16 compiled. Running 16 (10 masked) costs 0.4 s, compiling
    # 6 costs 3 s: reuse
    assert c.next(6, (16,)) == 16
    c.compile = 0.01  # a compilation cheaper than the masked generations: a short final chunk
    assert c.next(6, (16,)) == 6
    c.generation = 0.5  # 16 generations would take 8 s: chunks of about a second instead
    c.compile = 100.0
    assert c.next(6, (16,)) == 2


def _triangle():
    model = load_model(TRIANGLE)
    return model, simulate(model, 40, 60.0)


def _evolve(problem, settings, seconds: float, stop: int, every=None):
    with jax.enable_x64(True):
        strategy = strategies.make("es", problem, settings, jnp.float64)
        loop = evolve.Evolution(
            strategy, problem, jnp.float64, total=stop, requested=64, display=Display(1)
        )
        loop.chunking.seconds = seconds
        init_key, gen_key = evolve.keys(settings.seed)
        state = loop.start(init_key)
        lengths, rows = [], []
        for latest, row in loop.run(gen_key, state, stop, every):
            state = latest
            lengths.append(len(row["generation"]))
            rows.append(row)
        history = {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}
        return np.asarray(state.strategy.genes), history, lengths, loop


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_results_do_not_depend_on_the_chunk_lengths():
    model, traj = _triangle()
    settings = FitSettings(population=16, generations=40, seed=3, refine="none")
    with jax.enable_x64(True):
        problem = identification(model, traj, settings).problem
    tiny = _evolve(problem, settings, 1e-9, 40)  # chunks of one generation
    whole = _evolve(problem, settings, 1e9, 40)  # one chunk
    aligned = _evolve(problem, settings, 1e9, 40, every=15)  # no chunk crosses 15 or 30
    assert set(tiny[2]) == {1} and whole[2] == [40]
    assert np.cumsum(aligned[2]).tolist() == [15, 30, 40]
    for other in (whole, aligned):
        np.testing.assert_array_equal(tiny[0], other[0])
        for k in tiny[1]:
            np.testing.assert_array_equal(tiny[1][k], other[1][k])


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_a_short_fit_compiles_one_chunk_and_checkpoints_at_multiples(tmp_path):
    model, traj = _triangle()
    settings = FitSettings(population=24, generations=10, seed=1, refine="none")
    with jax.enable_x64(True):
        problem = identification(model, traj, settings).problem
    _, history, lengths, loop = _evolve(problem, settings, 1.0, 10)
    assert lengths == [10] and list(loop._compiled) == [10]
    assert history["generation"].tolist() == list(range(1, 11))
    # a fit checkpoints exactly every checkpoint_every generations, whatever the chunk length
    run = tmp_path / "run"
    fit(
        TRIANGLE,
        traj,
        FitSettings(population=24, generations=50, checkpoint_every=15, refine="none"),
        run,
    )
    saved = sorted(int(p.stem.split("-")[-1]) for p in (run / "checkpoints").glob("gen-*.npz"))
    assert saved == [45, 50], saved  # the two newest are kept
