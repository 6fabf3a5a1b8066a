"""Every integrator and substep count identifies the forces that generated the data.

The audit's case: a 4-particle, 6-bond viscoelastic tetrahedron (18 free parameters), 150
frames at 50 Hz, simulated with the same integrator and substeps as the fit. The start
velocity of each one-step prediction must be the one the integrator carries at the recorded
frame (``physics.start_velocity``); with the plain backward difference, Verlet inflated every
force by about 2 and N Euler substeps by about 2N/(N+1), while the fit error stayed tiny.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from activebonds.identify import fit
from activebonds.identify.costs.windows import make_cost, make_windows, rms_mm
from activebonds.model import load_model
from activebonds.physics import advance, start_velocity
from activebonds.simulation import simulate
from helpers import ROOT

TETRA = ROOT / "tests" / "models" / "tetra.toml"
CASES = [("euler", 1), ("euler", 4), ("euler", 10), ("verlet", 1), ("verlet", 4), ("verlet", 10)]


@pytest.fixture(scope="module")
def truth():
    jax.config.update("jax_enable_x64", True)
    return load_model(TETRA)


def recording(model, method, substeps):
    return simulate(model, 150, 50.0, substeps=substeps, integrator=method)


@pytest.mark.parametrize(("method", "substeps"), CASES)
def test_start_velocity_is_the_integrators_own(truth, method, substeps):
    """From two frames of a simulated recording, start_velocity returns the velocity the
    simulation carried at the second one (the backward difference lags by half a frame)."""
    p, topo = truth.params, truth.topology
    x0, v0 = (np.asarray(a) for a in truth.initial_state())
    dt = 0.02
    states = [(x0, v0)]
    for _ in range(3):
        x, v = advance(p, topo, *states[-1], dt, substeps, method)
        states.append((np.asarray(x), np.asarray(v)))
    (x1, _), (x2, v2) = states[1], states[2]
    v = np.asarray(start_velocity(p, topo, x1, x2, dt, substeps, method))
    scale = np.abs(v2).max()
    np.testing.assert_allclose(v, v2, rtol=0, atol=1e-7 * scale)
    lag = np.abs((x2 - x1) / dt - v2).max()
    if (method, substeps) != ("euler", 1):
        assert lag > 1e-4 * scale  # the naive estimate is measurably wrong here


@pytest.mark.parametrize(("method", "substeps"), CASES)
def test_cost_vanishes_at_the_truth(truth, method, substeps):
    """On data the same scheme generated, the true parameters predict every frame (to the
    fixed-point tolerance: 1e-6 of the RMS second difference; the plain backward difference
    leaves errors of order 1e-1 of it)."""
    data = recording(truth, method, substeps)
    windows = make_windows(data.positions, data.mask, data.dt, 1)
    cost = jax.jit(make_cost(truth, windows, substeps, method))
    rms = float(rms_mm(cost(truth.layout.initial())[0], windows.n_terms))
    signal = np.sqrt(np.mean(np.sum(np.diff(data.positions, 2, axis=0) ** 2, -1))) * 1000
    assert rms < 1e-6 * signal, (rms, signal)


def _recovery(truth, method, substeps, population=300, generations=4000, refine="none"):
    data = recording(truth, method, substeps)
    result = fit(
        truth,
        data,
        bonds="model",
        population=population,
        generations=generations,
        seed=0,
        substeps=substeps,
        integrator=method,
        refine=refine,
    )
    got = result.model.layout.natural(result.genome)
    want = truth.layout.natural(truth.layout.initial())
    return np.abs(got / want - 1.0), result


# (method, substeps, tolerance, population, generations, refine): the ES alone on the audit's
# budget, 300 x 4,000, at one substep. At 4 and 10 substeps, whose evaluations cost 4-50x a
# one-substep one, the mechanism under test (the start velocity the cost uses) is checked on
# the cost's own optimum: a short ES (100 x 300, from the same uniform start) then the fit's
# default Levenberg-Marquardt refinement on the same cost, at the same tolerance (the ES alone
# at 300 x 4,000 took 20 minutes for euler-4 on a 2-core machine).
RECOVERY = [
    pytest.param("euler", 1, 1e-3, 300, 4000, "none", id="euler-1", marks=pytest.mark.slow),
    pytest.param("verlet", 1, 5e-3, 300, 4000, "none", id="verlet-1", marks=pytest.mark.slow),
    pytest.param("euler", 4, 5e-3, 100, 300, "lm", id="euler-4", marks=pytest.mark.slow),
    pytest.param("verlet", 4, 5e-3, 100, 300, "lm", id="verlet-4", marks=pytest.mark.slow),
    pytest.param("euler", 10, 5e-3, 100, 300, "lm", id="euler-10", marks=pytest.mark.slow),
    pytest.param("verlet", 10, 5e-3, 100, 300, "lm", id="verlet-10", marks=pytest.mark.slow),
]


@pytest.mark.timeout(2400)
@pytest.mark.parametrize(
    ("method", "substeps", "tolerance", "population", "generations", "refine"), RECOVERY
)
def test_fit_recovers_every_parameter(
    truth, method, substeps, tolerance, population, generations, refine
):
    """The audit's recovery (from a uniform start within the bounds): every one of the 18
    parameters within 0.1 % (Euler, one substep) or 0.5 % (the others); before the
    start-velocity fix Verlet gave +98 % stiffness and 4 Euler substeps +60 %."""
    rel, result = _recovery(truth, method, substeps, population, generations, refine)
    assert rel.max() < tolerance, dict(zip(result.model.layout.genes, rel, strict=True))


def test_an_unsolvable_start_is_a_failed_candidate_not_a_biased_one(truth):
    """Stiff, heavily damped parameters for the frame interval: the fixed point of the start
    state does not converge in its rounds, so the velocity is NaN (the candidate costs +inf
    and is counted as failed) instead of silently wrong."""
    binary = {
        **truth.params.bonds["binary"],
        "stiffness": np.full(6, 5000.0),
        "damping": np.full(6, 60.0),
    }
    p = truth.params._replace(bonds={**truth.params.bonds, "binary": binary})
    x0, v0 = (np.asarray(a) for a in truth.initial_state())
    x1, _ = advance(p, truth.topology, x0, v0, 0.02, 2, "euler")
    v = np.asarray(start_velocity(p, truth.topology, x0, np.asarray(x1), 0.02, 2, "euler"))
    assert np.isnan(v).all()
    # the same parameters with one substep need no solve: exact, finite
    x1, v1 = advance(p, truth.topology, x0, v0, 0.02, 1, "euler")
    v = np.asarray(start_velocity(p, truth.topology, x0, np.asarray(x1), 0.02, 1, "euler"))
    np.testing.assert_allclose(v, np.asarray(v1), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(("method", "substeps"), [("euler", 2), ("verlet", 2)])
def test_a_body_at_60_hz_has_its_start_velocity_solved(truth, method, substeps):
    """A body's springs at 60 Hz (500 N/m and 5 N s/m per kg: the fixed point contracts by
    about 0.3 a round): the start velocity is the integrator's own to 1e-6 relative. With 3
    rounds every such start stayed ~1e-3 off and was NaN, so a 41-marker shot model's
    one-step check read NaN and rejected it."""
    dt = 1.0 / 60.0
    m = np.asarray(truth.params.mass)
    scale = float(np.min(m))
    binary = {
        **truth.params.bonds["binary"],
        "stiffness": np.full(6, 500.0 * scale),
        "damping": np.full(6, 5.0 * scale),
    }
    p = truth.params._replace(bonds={**truth.params.bonds, "binary": binary})
    x0, v0 = (np.asarray(a) for a in truth.initial_state())
    x1, v1 = (np.asarray(a) for a in advance(p, truth.topology, x0, v0, dt, substeps, method))
    v = np.asarray(start_velocity(p, truth.topology, x0, x1, dt, substeps, method))
    np.testing.assert_allclose(v, v1, rtol=1e-6, atol=1e-6 * float(np.abs(v1).max()))
    few = np.asarray(start_velocity(p, truth.topology, x0, x1, dt, substeps, method, 3))
    assert np.isnan(few).all()  # the old 3 rounds: not converged


def test_newton_solves_the_start_the_fixed_point_cannot_and_differentiates_it(truth):
    """Damped springs whose integrator is stable at 2 Euler substeps of 10 ms but whose
    start's fixed point diverges (it contracts by about dt c / m: 0.02 x 60 / 0.8 here, three
    bonds of 20 N s/m on the lightest particle): Newton's method on the exact
    Jacobian (``newton=True``, what a single parameter vector's least squares, checks and
    predictions use) returns the velocity the integrator carried, to 1e-9 relative, and its
    implicit derivative in the damping equals a central difference of the solve itself."""
    p = _stiff_damped(truth, damping=20.0)
    x0, v0 = (np.asarray(a) for a in truth.initial_state())
    x1, v1 = (np.asarray(a) for a in advance(p, truth.topology, x0, v0, 0.02, 2, "euler"))
    fixed_point = start_velocity(p, truth.topology, x0, x1, 0.02, 2, "euler")
    assert np.isnan(np.asarray(fixed_point)).all()

    @jax.jit
    def solved(damping):
        q = _stiff_damped(truth, damping)
        return start_velocity(q, truth.topology, x0, x1, 0.02, 2, "euler", newton=True)

    v = np.asarray(solved(20.0))
    np.testing.assert_allclose(v, v1, rtol=0, atol=1e-9 * np.abs(v1).max())
    _, dv = jax.jvp(solved, (20.0,), (1.0,))
    eps = 1e-3
    central = (np.asarray(solved(20.0 + eps)) - np.asarray(solved(20.0 - eps))) / (2 * eps)
    assert np.abs(np.asarray(dv)).max() > 1e-4  # the start's velocity does depend on it
    np.testing.assert_allclose(np.asarray(dv), central, rtol=0, atol=1e-6 * np.abs(central).max())


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_the_restart_residuals_vanish_where_the_population_cost_cannot_start(truth):
    """Data the damped tetrahedron above generated (2 Euler substeps at 50 Hz): the
    population's cost (fixed-point starts) is +inf at the truth, and so are the residuals
    by default; with Newton's starts (``newton=True``) they vanish there."""
    from activebonds.identify.costs.windows import make_residuals

    p = _stiff_damped(truth, damping=20.0)
    model, layout = truth, truth.layout
    genome = np.asarray(layout.initial())
    names = [(g.kind, g.field) for g in layout.genes]
    for i, (kind, field) in enumerate(names):
        if kind == "binary" and field == "stiffness":
            genome[i] = np.log(1000.0) if layout.log[i] else 1000.0
        elif kind == "binary" and field == "damping":
            genome[i] = np.log(20.0) if layout.log[i] else 20.0
    params = layout.decode(genome)
    np.testing.assert_allclose(
        np.asarray(params.bonds["binary"]["damping"]), np.asarray(p.bonds["binary"]["damping"])
    )
    x, v = (np.asarray(a) for a in truth.initial_state())
    frames = [x]
    for _ in range(20):
        x, v = (np.asarray(a) for a in advance(params, truth.topology, x, v, 0.02, 2, "euler"))
        frames.append(x)
    windows = make_windows(np.stack(frames), np.ones((21, x.shape[0]), bool), 0.02, 1)
    total, _ = make_cost(model, windows, 2, "euler")(genome)
    assert not np.isfinite(float(total))
    assert np.isnan(np.asarray(make_residuals(model, windows, 2, "euler")(genome))).any()
    residuals = np.asarray(make_residuals(model, windows, 2, "euler", newton=True)(genome))
    assert np.abs(residuals).max() < 1e-9


def _stiff_damped(truth, damping, stiffness=1000.0):
    binary = {
        **truth.params.bonds["binary"],
        "stiffness": np.full(6, stiffness),
        "damping": jnp.full(6, damping),
    }
    return truth.params._replace(bonds={**truth.params.bonds, "binary": binary})


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_refinement_whose_start_the_fixed_point_cannot_solve_takes_newtons_starts():
    """The damped tetrahedron above (20 N s/m on every bond, stiffnesses the file's), its
    recording made at 2 Euler substeps: from 2 % off the truth, the one-step refinement's
    start cannot be computed with the fixed point's start velocities (every one diverges),
    so its residuals are rebuilt with Newton's, and it recovers every parameter to 1e-6."""
    from activebonds.identify.problem import identification
    from activebonds.identify.settings import FitSettings
    from activebonds.identify.solvers.refine import Refinement
    from activebonds.model import loads_model

    model = loads_model(TETRA.read_text().replace("max = 10.0", "max = 100.0"), "tetra")
    layout = model.layout
    truth = np.asarray(layout.initial(), np.float64)
    damping = [i for i, g in enumerate(layout.genes) if g.field == "damping"]
    truth[damping] = np.log(20.0) if layout.log[damping[0]] else 20.0
    traj = simulate(model.with_genome(truth), 40, 50.0, substeps=2, integrator="euler")
    settings = FitSettings(horizon=(1,), cost="restart", substeps=2, integrator="euler")
    refinement = Refinement(identification(model, traj, settings), settings)
    start = layout.natural(truth) * 1.02
    start[layout.log] = np.log(start[layout.log])
    stage = refinement.stage(1, start)
    assert stage.accepted and refinement._newton, stage.message
    found = layout.natural(np.asarray(stage.genome))
    np.testing.assert_allclose(found, layout.natural(truth), rtol=1e-6)


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_predictions_from_a_recording_take_newtons_starts_where_the_fixed_point_fails():
    """The damped tetrahedron's own recording (2 Euler substeps): its one-step predictions
    and a free run from its first frames reproduce it (the fixed point's starts are NaN
    there: the predictions are run again with Newton's)."""
    from activebonds.identify.judge.predictions import free_run, one_step
    from activebonds.model import loads_model

    model = loads_model(TETRA.read_text().replace("max = 10.0", "max = 100.0"), "tetra")
    layout = model.layout
    genome = np.asarray(layout.initial(), np.float64)
    damping = [i for i, g in enumerate(layout.genes) if g.field == "damping"]
    genome[damping] = np.log(20.0) if layout.log[damping[0]] else 20.0
    truth = model.with_genome(genome)
    traj = simulate(truth, 30, 50.0, substeps=2, integrator="euler")
    x = np.asarray(traj.positions)
    predicted = one_step(truth, x, traj.dt, substeps=2, method="euler")
    np.testing.assert_allclose(predicted[2:], x[2:], rtol=0, atol=1e-9)
    run = free_run(truth, x, traj.dt, substeps=2, method="euler")[0]
    np.testing.assert_allclose(run, x, rtol=0, atol=1e-8)
