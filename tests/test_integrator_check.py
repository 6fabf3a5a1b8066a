"""The substeps check (identify/judge/integrator_check.py): a fit at one step per frame of a motion
finer than the frames is flagged with the parameters' move, toward the truth; a fit the
frames resolve is not."""

import numpy as np
import pytest

from activebonds.data import Trajectory
from activebonds.identify.costs.windows import make_windows
from activebonds.identify.judge import integrator_check, uncertainty
from activebonds.identify.problem import identification
from activebonds.identify.settings import FitSettings
from activebonds.identify.solvers.lsq import least_squares
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


def test_which_fits_are_checked_and_how_the_warning_reads():
    def settings(n, method):
        return FitSettings(substeps=n, integrator=method)

    assert integrator_check.applies(settings(1, "verlet"))
    assert integrator_check.applies(settings(4, "euler"))
    assert not integrator_check.applies(settings(5, "euler"))
    assert not integrator_check.applies(settings(2, "verlet"))
    assert integrator_check.finer(settings(3, "euler")) == 12
    moved = integrator_check.SubstepsCheck(
        12, 4.2, "spring A-B stiffness", "k", 10.0, 11.0, 2, 9, 3
    )
    warning = moved.warning()
    assert warning.startswith("at --substeps 12 the parameters move: 2 of 9")
    assert "3 steps per frame are too coarse" in warning and warning.endswith("--substeps 12")
    assert uncertainty.warnings("restart", 10, 3, (), moved) == [warning]
    one = integrator_check.SubstepsCheck(4, 4.2, "spring A-B stiffness", "k", 10.0, 11.0, 2, 9)
    assert "one step per frame is too coarse" in one.warning()


@pytest.mark.slow  # two fits at 2 substeps: in pytest -m slow (every landing)
def test_an_euler_fit_at_a_few_substeps_is_checked_at_four_times_as_many(tmp_path):
    """The advice's own `--substeps 4` (Euler) can still be too coarse (a new user's MuJoCo
    fit: intervals that missed the truth, no warning): a fit at 2 Euler substeps of the
    triangle simulated at 20 is checked at 8, flagged, and moved toward the truth; Verlet at
    2 substeps is not checked."""
    from activebonds.identify import fit

    model = load_model(TRIANGLE)
    recording = simulate(model, 200, 60.0, substeps=20)
    options = dict(population=8, generations=2, init="lsq", substeps=2)
    result = fit(model, recording, out=tmp_path / "euler", integrator="euler", **options)
    record = result.records["uncertainty"]
    checked = record["substeps_check"]
    assert checked["substeps"] == 8 and checked["fitted"] == 2
    assert checked["moved"] >= 1 and checked["largest_sd"] > 3
    genes = [g.name for g in model.layout.genes]
    true = dict(zip(genes, model.layout.natural(model.layout.initial()), strict=True))[
        checked["name"]
    ]
    assert abs(checked["after"] - true) < 0.5 * abs(checked["before"] - true)
    (warning,) = [w for w in record["warnings"] if w.startswith("at --substeps 8")]
    assert "2 steps per frame are too coarse" in warning and "refit with --substeps 8" in warning
    verlet = fit(model, recording, out=tmp_path / "verlet", integrator="verlet", **options)
    assert "substeps_check" not in verlet.records["uncertainty"]


TWO_MASSES = """
name = "two"
dimension = 3

[[particle]]
name = "A"
mass = 0.3
position = [0.0, 0.0, 0.0]
velocity = [0.0, 0.0, 0.0]

[[particle]]
name = "B"
mass = 0.5
position = [0.3, 0.0, 0.0]
velocity = [0.5, 0.2, 0.0]

[[bond]]
kind = "binary"
particles = ["A", "B"]
stiffness = { value = STIFFNESS, min = 1.0, max = 100000.0 }
rest_length = { value = 0.25, min = 0.1, max = 0.5 }
damping = { value = 0.0, min = 0.0, max = 10.0 }
"""


@pytest.mark.parametrize("stiffness, bias", [(500.0, -0.02205), (4000.0, -0.16559)])
def test_a_stiffness_fitted_at_one_step_a_frame_is_as_far_off_as_the_modes_say(stiffness, bias):
    """Two masses on a spring, simulated at 50 Verlet substeps a frame (100 Hz) and fitted by
    the exact one-step least squares at one Euler step: the stiffness comes out low by the
    bias of the integrator's dispersion at the fitted frequency (-2.2 % at 0.51 rad a step,
    -16.6 % at 1.33), which :func:`modes.stiffness_bias` predicts to 0.01 %; the warning
    names the substeps that bring it within 1 %."""
    from activebonds.identify.judge import modes
    from activebonds.model import loads_model
    from activebonds.simulation import simulate

    truth = loads_model(TWO_MASSES.replace("STIFFNESS", str(stiffness)))
    data = simulate(truth, 200, 100.0, substeps=50, integrator="verlet")
    fit = least_squares(truth, make_windows(data.positions, data.mask, data.dt, 1))
    fitted = truth.with_genome(fit.genome)
    found = float(np.asarray(fitted.params.bonds["binary"]["stiffness"])[0]) / stiffness - 1.0
    assert found == pytest.approx(bias, abs=2e-4)  # the bias itself, measured
    omega = modes.fastest(fitted, data.positions[:3])
    assert modes.stiffness_bias(omega, data.dt) == pytest.approx(found, abs=1e-4)
    more = modes.substeps_for(omega, data.dt)
    assert abs(modes.stiffness_bias(omega, data.dt / more)) <= modes.TOLERANCE
    assert abs(modes.stiffness_bias(omega, data.dt / (more - 1))) > modes.TOLERANCE
    words = modes.warning(omega, data.dt, 1)
    assert f"refit with --substeps {more}" in words and f"{100 * found:+.1f} %" in words
    assert modes.warning(omega, data.dt, more) is None
    assert modes.stiffness_bias(2.5 / data.dt, data.dt) is None  # past the stability limit


def test_an_exact_fit_of_a_simulated_recording_is_not_told_to_refit(tmp_path):
    """A recording made by `simulate` at one Euler substep, fitted exactly at one: the check's
    move is real (a finer integration is another model of these frames) but 'one step per
    frame is too coarse ... refit with --substeps 4' misled a new user; the warning says the
    fit is exact instead, with the same numbers."""
    import json

    from activebonds.identify import fit

    model = load_model(TRIANGLE)
    fit(model, simulate(model, 120, 100.0), bonds="standard", population=8, generations=3,
        out=tmp_path / "run", cost="restart")  # fmt: skip
    record = json.loads((tmp_path / "run" / "uncertainty.json").read_text())
    assert record["sigma_mm"] < integrator_check.EXACT_MM
    check = record["substeps_check"]
    assert check["moved"] >= 1
    said = [w for w in record["warnings"] if "--substeps 4" in w]
    assert len(said) == 1 and said[0].startswith("the fit is exact at one step per frame")
    assert "refit with --substeps" not in said[0] and check["parameter"] in said[0]
