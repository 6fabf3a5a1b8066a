"""The substeps check (identify/integrator_check.py): a fit at one step per frame of a motion
finer than the frames is flagged with the parameters' move, toward the truth; a fit the
frames resolve is not."""

import numpy as np
import pytest

from activebonds.data import Trajectory
from activebonds.identify import integrator_check, uncertainty
from activebonds.identify.cost import make_windows
from activebonds.identify.lsq import least_squares
from activebonds.identify.problem import identification
from activebonds.identify.settings import FitSettings
from activebonds.model import load_model
from activebonds.runtime import float64
from activebonds.simulation import simulate
from helpers import TRIANGLE


@float64
def _checked(rate: float, noise: float):
    """The triangle simulated at 20 substeps per frame, fitted exactly at one, checked."""
    model = load_model(TRIANGLE)
    traj = simulate(model, 200, rate, substeps=20)
    rng = np.random.default_rng(0)
    pos = traj.positions + rng.normal(0.0, noise, traj.positions.shape)
    traj = Trajectory(positions=pos, markers=traj.markers, rate=rate, mask=traj.mask, source="")
    settings = FitSettings()
    ident = identification(model, traj, settings)
    fit = least_squares(ident.model, make_windows(traj.positions, traj.mask, traj.dt, 1))
    report = uncertainty.estimate(ident, settings, fit.genome, 1, "restart")
    genes = [g.name for g in model.layout.genes]
    truth = dict(zip(genes, model.layout.natural(model.layout.initial()), strict=True))
    return integrator_check.check(ident, settings, fit.genome, 1, report.estimates), truth


def test_one_step_per_frame_of_a_finer_motion_is_flagged_and_the_move_goes_to_the_truth():
    checked, truth = _checked(60.0, 1e-6)
    assert checked.moved >= 3 and checked.largest_sd > 10
    # the first-order move lands nearer the truth (the data's integrator is finer still)
    true = truth[checked.name]
    assert abs(checked.after - true) < 0.5 * abs(checked.before - true)
    warning = uncertainty.warnings("restart", 1, 1, (), checked)[1]
    assert warning.startswith("at --substeps 4 the parameters move:")
    assert "refit with --substeps 4" in warning and checked.parameter in warning


def test_a_motion_the_frames_resolve_is_not_flagged():
    checked, _ = _checked(300.0, 1e-5)
    assert checked.moved == 0 and checked.largest_sd < 0.5
    # measured and clean: no substeps warning, only the one-step cost's
    assert len(uncertainty.warnings("restart", 1, 1, (), checked)) == 1


def test_a_check_not_made_keeps_the_warning_in_words():
    words = uncertainty.warnings("restart", 1, 1, (), "its Jacobian would take 900 MiB")
    assert "64 % coverage" in words[1]


@pytest.mark.parametrize("noise", [5e-4])
def test_noise_alone_does_not_raise_the_flag(noise):
    checked, _ = _checked(120.0, noise)
    assert checked.moved == 0


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_shooting_fit_at_one_substep_is_checked_by_its_normal_equations(tmp_path):
    """`fit` with --cost shooting at one substep of the triangle simulated at 20: the
    uncertainty record carries the check, which flags the fit and moves it toward the truth."""
    from activebonds.identify import fit

    model = load_model(TRIANGLE)
    recording = simulate(model, 200, 60.0, substeps=20)
    result = fit(
        model,
        recording,
        out=tmp_path / "run",
        population=8,
        generations=2,
        init="lsq",
        cost="shooting",
        horizon=(10,),
    )
    record = result.records["uncertainty"]
    assert record["cost"] == "shooting"
    checked = record["substeps_check"]
    assert checked["moved"] >= 3 and checked["largest_sd"] > 10
    genes = [g.name for g in model.layout.genes]
    true = dict(zip(genes, model.layout.natural(model.layout.initial()), strict=True))[
        checked["name"]
    ]
    assert abs(checked["after"] - true) < 0.5 * abs(checked["before"] - true)
    assert any(w.startswith("at --substeps 4 the parameters move") for w in record["warnings"])


def test_a_contact_model_on_the_restart_cost_is_not_checked_and_says_why():
    """Forward mode over the parameters through a contact's Newton start velocities left XLA
    waiting (the tutorial's fit): such a check is not made, and the warning stays in words."""
    from activebonds.data import read_trajectory
    from activebonds.data.bundled import dataset
    from helpers import EXAMPLES

    model = load_model(EXAMPLES / "horse_trot_ground.toml")
    recording = read_trajectory(dataset("horse-trot").path).window(0, 40)
    settings = FitSettings()
    ident = identification(model, recording, settings)
    genome = np.asarray(ident.model.layout.initial(), np.float64)
    why = integrator_check.check(ident, settings, genome, 1, [])
    assert why.startswith("a contact's start velocities are Newton solves")
    assert "64 % coverage" in uncertainty.warnings("restart", 1, 1, (), why)[1]
