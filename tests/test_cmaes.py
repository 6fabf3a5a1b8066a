"""CMA-ES (evosax) as a strategy: ``--optimizer cmaes``.

* on a quadratic bowl it converges to machine precision in a small budget, every candidate
  within the bounds;
* on the synthetic triangle, through ``fit``, it recovers the parameters (RMS < 1e-6 mm) and
  ends far below the paper's ES at the same population x generations;
* through ``fit`` with a run directory, stopped half way and resumed, it ends exactly as one
  uninterrupted fit (history and best model);
* its state (evosax's pytree) round-trips through the checkpoint's flattening, paths and
  dtypes.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from activebonds.identify import fit, resume
from activebonds.identify.costs.windows import Display
from activebonds.identify.rundir import RunDir
from activebonds.identify.search import evolve
from activebonds.identify.search.cmaes import CMAES
from activebonds.identify.search.strategy import Problem
from helpers import bowl_problem
from reliability_runner import EXAMPLES

pytestmark = pytest.mark.timeout(120)


def _bowl(n_genes: int = 5) -> Problem:
    return bowl_problem(n_genes)


def _run(problem, strategy, generations, seed=0):
    loop = evolve.Evolution(
        strategy, problem, jnp.float64, total=generations, requested=50, display=Display(1)
    )
    init_key, gen_key = evolve.keys(seed)
    state = loop.start(init_key)
    rows = []
    for latest, row in loop.run(gen_key, state, generations):
        state = latest
        rows.append(row)
    return loop, init_key, state, {k: np.concatenate([r[k] for r in rows]) for k in rows[0]}


def test_cmaes_reaches_the_bottom_of_a_bowl_in_a_small_budget():
    with jax.enable_x64(True):
        problem = _bowl()
        strategy = CMAES(problem, population=12, sigma_init=0.2, dtype=jnp.float64)
        loop, init_key, state, history = _run(problem, strategy, 120)
        genome, cost, local = strategy.best(state.strategy)
    assert float(cost) < 1e-12  # 12 x 120 = 1440 evaluations of a 5-gene bowl
    assert np.all(np.diff(history["best_cost"]) <= 0)
    np.testing.assert_allclose(genome, np.linspace(0.2, 0.8, 5), atol=1e-6)
    assert float(local.sum()) == pytest.approx(float(cost))
    assert history["sigma"][-1] < 1e-3 * 0.2  # the step size shrank as it converged


def test_every_evaluated_candidate_is_within_the_bounds():
    seen: list[np.ndarray] = []
    with jax.enable_x64(True):
        # a bowl whose optimum is on the lower bound of every gene: half the samples fall out
        target = jnp.zeros(4)

        def evaluate(g):
            jax.debug.callback(lambda x: seen.append(np.asarray(x)), g)
            return jnp.sum((g - target) ** 2), (g - target) ** 2

        problem = Problem(
            evaluate, np.full(4, -0.0), np.full(4, 2.0), np.arange(4, dtype=np.int32),
            np.arange(4, dtype=np.int32)[:, None],
        )  # fmt: skip
        strategy = CMAES(problem, population=8, sigma_init=0.5, dtype=jnp.float64)
        _, _, state, _ = _run(problem, strategy, 30)
    genes = np.stack(seen)
    assert genes.shape[0] == 1 + 8 * 30  # the start (the centre), then 30 generations
    assert genes.min() >= 0.0 and genes.max() <= 2.0
    np.testing.assert_array_equal(genes[0], np.ones(4))  # the mean starts at the centre
    assert float(strategy.best(state.strategy)[1]) < 1e-3  # and it went towards the corner


def test_the_state_round_trips_through_the_checkpoint_flattening():
    with jax.enable_x64(True):
        problem = _bowl()
        strategy = CMAES(problem, population=12, sigma_init=0.2, dtype=jnp.float64)
        loop, init_key, state, _ = _run(problem, strategy, 7)
        flat = RunDir.flatten_state(state)
        back = RunDir.unflatten_state(flat, loop.template(init_key))
    assert {"es.mean", "es.C", "es.std", "es.generation_counter", "genes", "cost"} <= set(flat)
    assert flat["es.generation_counter"].dtype == np.int32 and flat["es.C"].dtype == np.float64
    for a, b in zip(jax.tree.leaves(state), jax.tree.leaves(back), strict=True):
        assert a.dtype == b.dtype and np.array_equal(np.asarray(a), np.asarray(b))
    assert jax.tree.structure(state) == jax.tree.structure(back)


@pytest.fixture(scope="module")
def triangle():
    from activebonds.model import load_model
    from activebonds.simulation import simulate

    model = load_model(EXAMPLES / "triangle.toml")
    return model, simulate(model, 30, 60.0)


def test_cmaes_recovers_the_triangle_and_beats_the_es_at_equal_evaluations(triangle):
    truth, traj = triangle
    budget = {"population": 16, "generations": 300, "seed": 0, "refine": "none"}  # search alone
    cma = fit(truth, traj, optimizer="cmaes", **budget)
    es = fit(truth, traj, optimizer="es", **budget)
    assert cma.status == "completed" and cma.settings.optimizer == "cmaes"
    assert cma.rms_mm < 1e-6
    for field in ("stiffness", "rest_length", "damping"):
        want = np.asarray(truth.params.bonds["binary"][field])
        got = np.asarray(cma.model.params.bonds["binary"][field])
        np.testing.assert_allclose(got, want, rtol=1e-6, err_msg=field)
    # 16 x 300 = 4800 evaluations each: CMA-ES far below the paper's ES
    assert cma.cost < 1e-6 * es.cost
    reached = np.flatnonzero(cma.history["best_rms_mm"] < 1e-6)
    assert reached.size and reached[0] + 1 < 300  # generations CMA-ES needed
    assert not np.any(es.history["best_rms_mm"] < 1e-3)  # the ES is not near it yet


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_fit_stopped_half_way_and_resumed_equals_one_fit(triangle, tmp_path):
    truth, traj = triangle
    opts = {"optimizer": "cmaes", "population": 12, "seed": 3, "chunk": 20, "refine": "none"}
    whole = fit(truth, traj, out=tmp_path / "whole", generations=80, **opts)
    fit(truth, traj, out=tmp_path / "run", generations=40, **opts)
    seen: list[int] = []
    resumed = resume(tmp_path / "run", generations=80, progress=lambda g, n, b: seen.append(g))
    assert seen[0] == min(seen) == 40  # it continued from the stop, not from scratch
    assert resumed.status == "completed"
    assert set(resumed.history) == set(whole.history)
    for name, column in whole.history.items():
        assert np.array_equal(resumed.history[name], column), name
    assert np.array_equal(resumed.genome, whole.genome)
    assert resumed.cost == whole.cost
    for field in ("stiffness", "rest_length", "damping"):
        assert np.array_equal(
            resumed.model.params.bonds["binary"][field], whole.model.params.bonds["binary"][field]
        )
