"""The population form of the one-step cost equals the reference cost, vmapped, on every kind
of model; float32 evaluation stays within single-precision rounding; both force
accumulations give the same sums."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from activebonds.bonds.accumulate import accumulate
from activebonds.data import Trajectory, read_trajectory
from activebonds.identify.costs.windows import join_windows, make_cost, make_windows
from activebonds.identify.problem import identification
from activebonds.identify.search import population_cost
from activebonds.identify.search.population_cost import applies, make_population_cost
from activebonds.identify.settings import FitSettings
from activebonds.model import as_neural, load_model
from activebonds.simulation import simulate
from helpers import EXAMPLES, HORSE_LIMB, HORSE_TROT, TRIANGLE


def _genes(problem, n: int, seed: int = 0) -> jnp.ndarray:
    """Genomes spread over the middle half of every range (finite costs, saturated and
    unsaturated neurons alike)."""
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(problem.lower), np.asarray(problem.upper)
    return jnp.asarray(lo + (hi - lo) * rng.uniform(0.25, 0.75, (n, len(lo))))


def _compare(ident, n: int = 16, rtol: float = 1e-12):
    problem = ident.problem
    assert problem.evaluate_population is not None
    genes = _genes(problem, n)
    ref_cost, ref_local = jax.jit(jax.vmap(problem.evaluate))(genes)
    cost, local = jax.jit(problem.evaluate_population)(genes)
    assert np.all(np.isfinite(np.asarray(ref_cost)))
    np.testing.assert_allclose(np.asarray(cost), np.asarray(ref_cost), rtol=rtol, atol=0)
    np.testing.assert_allclose(np.asarray(local), np.asarray(ref_local), rtol=rtol, atol=1e-300)
    return np.asarray(ref_cost)


@pytest.mark.parametrize("bonds", ["standard", "neural"])
def test_paper_horse_equals_the_reference_cost(bonds):
    with jax.enable_x64(True):
        settings = FitSettings(markers=("Head", "Withers", "HFL"), frames=(0, 40), bonds=bonds)
        _compare(identification(load_model(HORSE_LIMB), read_trajectory(HORSE_TROT), settings))


@pytest.mark.parametrize(
    "name", ["horse_trot_ground.toml", "horse_trot_drive.toml"]
)  # gravity, free masses under a total, unary anchors, contacts, the rhythmic drive
def test_ground_horse_with_every_kind_equals_the_reference_cost(name):
    with jax.enable_x64(True):
        settings = FitSettings(frames=(100, 160))
        _compare(identification(load_model(EXAMPLES / name), read_trajectory(HORSE_TROT), settings))


def test_ternary_chain_and_a_recording_with_gaps_and_two_recordings():
    with jax.enable_x64(True):
        model = as_neural(load_model(EXAMPLES / "chain2d.toml"))
        a = simulate(model, 40, 60.0)
        positions = np.array(a.positions)
        mask = np.array(a.mask)
        mask[10:13, 1] = False  # a gap: the starts around it count nowhere
        positions[~mask] = np.nan
        gappy = Trajectory(positions, mask, a.markers, a.rate)
        b = simulate(model, 30, 60.0)
        ident = identification(model, [gappy, b], FitSettings())
        assert ident.windows.weight.sum() < ident.windows.weight.size  # the gap is there
        _compare(ident)


def test_the_gathered_spread_equals_the_dense_product(monkeypatch):
    with jax.enable_x64(True):
        settings = FitSettings(frames=(0, 30), bonds="neural")
        ident = identification(
            load_model(TRIANGLE), simulate(load_model(TRIANGLE), 30, 60.0), settings
        )
        dense = ident.problem.evaluate_population
        monkeypatch.setattr(population_cost, "DENSE_LIMIT", 0)
        gathered = make_population_cost(ident.model, ident.windows)
        genes = _genes(ident.problem, 8)
        np.testing.assert_allclose(
            np.asarray(jax.jit(gathered)(genes)[1]),
            np.asarray(jax.jit(dense)(genes)[1]),
            rtol=1e-13,
        )


def test_float32_evaluation_is_within_single_precision_rounding():
    with jax.enable_x64(True):
        settings = FitSettings(markers=("Head", "Withers", "HFL"), frames=(0, 200), bonds="neural")
        ident = identification(load_model(HORSE_LIMB), read_trajectory(HORSE_TROT), settings)
        f32 = make_population_cost(ident.model, ident.windows, dtype=jnp.float32)
        genes = _genes(ident.problem, 32)
        ref = np.asarray(jax.jit(jax.vmap(ident.problem.evaluate))(genes)[0])
        cost = np.asarray(jax.jit(f32)(genes)[0])
        assert cost.dtype == np.float32
        rel = np.abs(cost - ref) / ref
        assert rel.max() < 1e-4, rel.max()
        assert rel.max() > 0  # it really is float32


def test_the_population_form_applies_to_the_one_step_euler_cost_only():
    with jax.enable_x64(True):
        model = load_model(TRIANGLE)
        traj = simulate(model, 30, 60.0)
        w1 = make_windows(traj.positions, traj.mask, traj.dt, 1)
        w5 = make_windows(traj.positions, traj.mask, traj.dt, 5)
        assert applies(w1, 1, "euler")
        assert not applies(w5, 1, "euler")
        assert not applies(w1, 2, "euler")
        assert not applies(w1, 1, "verlet")
        assert make_population_cost(model, w1, 1, "verlet") is None
        for settings in (FitSettings(horizon=5), FitSettings(integrator="verlet")):
            assert identification(model, traj, settings).problem.evaluate_population is None
        # and the one-step cost of joined windows is the same function of the genome
        joined = join_windows([w1, w1])
        cost, ref = make_population_cost(model, joined), jax.vmap(make_cost(model, joined))
        genes = _genes(identification(model, traj, FitSettings()).problem, 4)
        np.testing.assert_allclose(
            np.asarray(cost(genes)[0]), np.asarray(ref(genes)[0]), rtol=1e-12
        )


def test_unrolled_and_gathered_force_sums_agree():
    rng = np.random.default_rng(3)
    n, k = 9, 40
    i, j = rng.integers(0, n, k), rng.integers(0, n, k)
    f, g = jnp.asarray(rng.normal(size=(k, 3))), jnp.asarray(rng.normal(size=(k, 3)))
    terms = [(i, 1, f), (j, -1, f), (j, 1, g)]
    expected = np.zeros((n, 3))
    np.add.at(expected, i, np.asarray(f))
    np.add.at(expected, j, -np.asarray(f))
    np.add.at(expected, j, np.asarray(g))
    for form in ("unrolled", "gathered", None):
        np.testing.assert_allclose(np.asarray(accumulate(n, terms, form)), expected, atol=1e-12)


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_mixed_precision_fit_recovers_the_triangle():
    """--precision mixed (the ES's one-step cost in float32) against a known truth: the ES
    alone gets within 5 % of every parameter, and its float64 refinement within 0.1 %; the
    fit is far below the zero-force baseline."""
    from activebonds.identify import fit
    from activebonds.identify.judge.baselines import zero_force_rms_mm

    model = load_model(TRIANGLE)
    data = simulate(model, 60, 60.0)
    options = dict(bonds="standard", population=100, generations=1500, seed=0)
    es = fit(model, data, precision="mixed", refine="none", **options)
    refined = fit(model, data, precision="mixed", refine="lm", **options)
    truth = model.params.bonds["binary"]
    for result, rtol in ((es, 0.05), (refined, 1e-3)):
        got = result.model.params.bonds["binary"]
        for field in ("stiffness", "rest_length", "damping"):
            np.testing.assert_allclose(got[field], truth[field], rtol=rtol, err_msg=field)
    zero = zero_force_rms_mm(data.positions, data.mask, data.dt)
    assert refined.rms_mm < 1e-3 * zero
