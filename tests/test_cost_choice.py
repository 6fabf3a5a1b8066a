"""The refinement's cost when the command line is not told (``fit --cost auto``), and the
check that keeps a shooting stage from ending worse than constant velocity."""

from __future__ import annotations

import re

import numpy as np
import pytest

import activebonds
from activebonds.identify.costs.choice import AFFORDABLE_UNKNOWNS, choose_cost
from activebonds.identify.costs.windows import constant_velocity_cost, make_windows, rms_mm
from activebonds.identify.problem import identification
from activebonds.identify.settings import FitSettings
from activebonds.identify.solvers.refine import Refinement
from activebonds.model import load_model, loads_model
from helpers import EXAMPLES, HORSE_LIMB, HORSE_TROT, cli


def test_constant_velocity_error_is_the_analytic_one_under_uniform_acceleration():
    """x(t) = a t^2 / 2: from the backward-difference velocity a (t - dt/2), k frames ahead
    the zero-force predictor is off by -a dt^2 k (k + 1) / 2."""
    dt, a, horizon = 0.01, np.array([0.3, -2.0, 9.81]), 4
    t = np.arange(40) * dt
    pos = 0.5 * t[:, None, None] ** 2 * a[None, None, :]  # one marker
    windows = make_windows(pos, np.ones((40, 1), bool), dt, horizon)
    k = np.arange(1, horizon + 1)
    per_start = np.sum((0.5 * dt**2 * k * (k + 1))[:, None] ** 2 * a**2 * windows.weight[0])
    expected = per_start * (windows.weight.sum(axis=(1, 2)) == horizon).sum()
    partial = windows.weight.sum(axis=(1, 2)) < horizon  # the last start: clipped terms
    for s in np.flatnonzero(partial):
        kk = k[windows.weight[s, :, 0] > 0]
        expected += np.sum((0.5 * dt**2 * kk * (kk + 1))[:, None] ** 2 * a**2)
    assert constant_velocity_cost(windows) == pytest.approx(expected, rel=1e-12)
    still = make_windows(
        0.2 + 0.7 * t[:, None, None] * np.ones((1, 1, 3)), np.ones((40, 1), bool), dt, 5
    )
    assert constant_velocity_cost(still) == pytest.approx(0.0, abs=1e-24)


def test_auto_shoots_where_a_window_is_small_and_says_why():
    settings, why = choose_cost(FitSettings(), n_genes=18, n_coordinates=12, horizon_given=False)
    assert settings.cost == "shooting" and settings.horizon == (10,)
    assert why.startswith("cost: shooting (auto") and "--cost restart" in why
    given = FitSettings(horizon=(5, 20))
    settings, _ = choose_cost(given, n_genes=18, n_coordinates=12, horizon_given=True)
    assert settings.cost == "shooting" and settings.horizon == (5, 20)


def test_auto_keeps_the_restart_cost_where_shooting_is_not_affordable_or_not_asked():
    big = AFFORDABLE_UNKNOWNS - 2 * 123 + 1  # one unknown too many with 41 markers in 3D
    settings, why = choose_cost(FitSettings(), n_genes=big, n_coordinates=123, horizon_given=False)
    assert settings.cost == "restart" and settings.horizon == (1,)
    assert f"{AFFORDABLE_UNKNOWNS + 1} unknowns" in why and "--cost shooting" in why
    settings, why = choose_cost(FitSettings(refine="none"), 18, 12, horizon_given=False)
    assert settings.cost == "restart" and "--refine none" in why


# rest lengths fixed at 0.8 m (the truth: 0.45-0.6 m): springs that push every particle away
# from where the recording goes; with their stiffness free the fit can only weaken them
LOOSE = re.sub(
    r"rest_length = \{[^}]*\}", "rest_length = 0.8", (EXAMPLES / "triangle.toml").read_text()
)
STIFF = re.sub(r"stiffness = \{[^}]*\}", "stiffness = 80.0", LOOSE)


def _stage(text: str):
    truth = load_model(EXAMPLES / "triangle.toml")
    traj = activebonds.simulate(truth, 40, 60.0)
    settings = FitSettings(cost="shooting", horizon=(10,))
    ident = identification(loads_model(text, "wrong"), traj, settings)
    stage = Refinement(ident, settings).stage(10, ident.model.layout.initial())
    baselines = {}
    for h in (1, 10):
        windows = make_windows(traj.positions, traj.mask, traj.dt, h)
        baselines[h] = float(rms_mm(constant_velocity_cost(windows), windows.n_terms))
    return stage, baselines


def test_a_model_that_loses_to_constant_velocity_is_not_shot():
    stage, baselines = _stage(STIFF)
    assert stage.cost == "restart" and stage.horizon == 1
    assert stage.message.startswith("not shot: the model's best 10-frame predictions")
    assert f"vs {baselines[10]:.4g} mm" in stage.message


def test_a_shot_model_that_loses_to_constant_velocity_is_rejected():
    stage, baselines = _stage(LOOSE)
    assert stage.cost == "restart" and stage.horizon == 1
    prefix = "the shot model was rejected: its 1-frame predictions are no better"
    assert stage.message.startswith(prefix) and f"vs {baselines[1]:.4g} mm" in stage.message


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_fit_on_a_recording_shoots_by_default_and_never_ends_worse_than_zero_force(tmp_path):
    """The demo's horse limb on the trot: the shot model loses to constant velocity one frame
    ahead (it trades the markers for continuity), so the refinement falls back to the
    one-step cost and the fit ends below the zero-force predictor."""
    run = tmp_path / "run"
    args = ("fit", HORSE_LIMB, HORSE_TROT, "--generations", "50", "--frames", "0:200")
    res = cli(*args, "--out", run)
    assert res.returncode == 0, res.stderr
    assert "cost: shooting (auto" in res.stdout
    assert "the shot model was rejected: its 1-frame predictions" in res.stdout
    lines = res.stdout.splitlines()
    best = next(ln for ln in lines if ln.startswith("completed: best RMS error "))
    zero = next(ln for ln in lines if ln.startswith("zero-force baseline on the same frames "))
    assert float(best.split()[4]) < float(zero.split()[-2])
