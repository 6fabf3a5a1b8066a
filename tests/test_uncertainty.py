"""The uncertainty report: Gauss-Newton standard errors, undetermined directions, coverage."""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest

from activebonds.experiments.coverage import coverage, trial
from activebonds.identify.judge.uncertainty import Z95, describe, from_jacobian
from activebonds.model import load_model
from helpers import TRIANGLE, cli_in_process


def test_linear_regression_matches_the_textbook_covariance():
    """For a linear model the Gauss-Newton covariance is s^2 (X^T X)^-1, exactly."""
    rng = np.random.default_rng(1)
    x = rng.normal(size=(200, 3)) * np.array([1.0, 1e3, 1e-3])  # units must not matter
    beta = np.array([2.0, -0.5e-3, 7e2])
    y = x @ beta + rng.normal(0.0, 0.1, 200)
    fit, *_ = np.linalg.lstsq(x, y, rcond=None)
    resid = x @ fit - y
    est, rank, cond, s2, dirs = from_jacobian(
        x, resid, ["a", "b", "c"], fit, np.full(3, 1e9), dof=197
    )
    s2_ref = resid @ resid / 197
    se_ref = np.sqrt(np.diag(s2_ref * np.linalg.inv(x.T @ x)))
    assert rank == 3 and np.isfinite(cond) and dirs == []
    np.testing.assert_allclose(s2, s2_ref, rtol=1e-12)
    np.testing.assert_allclose([e.std_error for e in est], se_ref, rtol=1e-9)
    for e, f, se in zip(est, fit, se_ref, strict=True):
        assert e.determined
        np.testing.assert_allclose([e.low, e.high], [f - Z95 * se, f + Z95 * se], rtol=1e-9)


def test_linear_intervals_cover_the_truth_95_percent():
    """Calibration of the formula itself: 400 noisy linear datasets, 3 parameters each."""
    rng = np.random.default_rng(2)
    beta = np.array([1.0, -2.0, 0.5])
    x = rng.normal(size=(60, 3))
    hits = []
    for _ in range(400):
        y = x @ beta + rng.normal(0.0, 0.3, 60)
        fit, *_ = np.linalg.lstsq(x, y, rcond=None)
        est, *_ = from_jacobian(x, x @ fit - y, ["a", "b", "c"], fit, np.full(3, 100.0), dof=57)
        hits += [e.low <= b <= e.high for e, b in zip(est, beta, strict=True)]
    assert 0.93 <= np.mean(hits) <= 0.97, np.mean(hits)


def test_a_singular_jacobian_is_named_not_printed():
    """Two parameters that only enter as a sum: both 'not determined', the pair named."""
    rng = np.random.default_rng(3)
    col = rng.normal(size=50)
    other = rng.normal(size=50)
    jac = np.stack([col, 2.0 * col, other], axis=1)  # b moves the residuals as 2 a does
    names = ["type:neck.stiffness", "type:neck.rest_length", "bond[2].damping"]
    est, rank, cond, _, dirs = from_jacobian(
        jac, rng.normal(size=50), names, np.ones(3), np.full(3, 10.0), dof=47
    )
    assert rank == 2 and cond == float("inf")
    assert [e.determined for e in est] == [False, False, True]
    assert est[0].std_error is None and est[0].low is None
    assert dirs == ["stiffness and rest_length of type:neck trade off"]
    assert est[0].note == dirs[0]


def test_mass_scale_is_named():
    names = ["mass:A.mass", "mass:B.mass", "bond[0].stiffness"]
    assert describe(names, np.array([0.5, 0.5, 0.7]), {0, 1}).startswith("mass scale")


def test_an_interval_wider_than_the_search_range_is_not_determined():
    rng = np.random.default_rng(4)
    jac = np.stack([rng.normal(size=40), 1e-6 * rng.normal(size=40)], axis=1)
    est, *_ = from_jacobian(jac, rng.normal(size=40), ["a", "b"], np.ones(2), np.ones(2), 38)
    assert est[0].determined and not est[1].determined
    assert est[1].note.startswith("interval wider than the search range")


def test_non_finite_jacobian_is_reported_not_raised():
    jac = np.array([[1.0, np.nan], [0.0, 1.0]])
    est, rank, *_ = from_jacobian(jac, np.zeros(2), ["a", "b"], np.ones(2), np.ones(2), 1)
    assert rank == 0 and not any(e.determined for e in est)


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_fit_writes_uncertainty_csv(tmp_path):
    """A fit of the noiseless triangle: every parameter determined, intervals tiny around it."""
    data = tmp_path / "tri.csv"
    assert (
        cli_in_process(
            "simulate", TRIANGLE, "--n-frames", "120", "--rate", "100", "--out", data
        ).returncode
        == 0
    )
    run = tmp_path / "run"
    r = cli_in_process(
        "fit", TRIANGLE, data, "--population", "30", "--generations", "100", "--out", run
    )
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader((run / "uncertainty.csv").read_text().splitlines()))
    model = load_model(TRIANGLE)
    truth = model.layout.natural(model.layout.initial())
    assert [row["parameter"] for row in rows] == [g.name for g in model.layout.genes]
    for row, t in zip(rows, truth, strict=True):
        assert row["determined"] == "yes"
        assert float(row["std_error"]) < 1e-6 * abs(t)
        assert abs(float(row["value"]) - t) < 1e-6 * abs(t)
    record = json.loads((run / "uncertainty.json").read_text())
    assert record["rank"] == len(rows) and record["directions"] == []
    report = tmp_path / "r.html"
    assert cli_in_process("report", run, "--out", report).returncode == 0
    assert "Uncertainty" in report.read_text()


@pytest.mark.slow
def test_pipeline_coverage_on_50_noisy_datasets():
    """Simulate, add 0.5 mm noise, fit (least squares, restart horizon 10, one shooting window),
    and check the 95 % intervals contain the truth 90-98 % of the time (pooled)."""
    model = load_model(TRIANGLE)
    trials = [trial(model, 200, 100.0, 5e-4, seed) for seed in range(50)]
    assert 0.90 <= coverage(trials) <= 0.98, coverage(trials)


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_a_parameter_without_effect_is_not_determined_in_a_fit(tmp_path):
    """A unary anchor whose spring and damper are fixed at 0 moves nothing: the fit's
    uncertainty.csv and report say 'not determined' for it, and give the others."""
    data = tmp_path / "tri.csv"
    assert (
        cli_in_process(
            "simulate", TRIANGLE, "--n-frames", "80", "--rate", "100", "--out", data
        ).returncode
        == 0
    )
    model = tmp_path / "m.toml"
    model.write_text(
        TRIANGLE.read_text()
        + '\n[[bond]]\nkind = "unary"\nparticles = ["A"]\nstiffness = 0.0\ndamping = 0.0\n'
        + "anchor = { value = [0.0, 0.0, 0.0], min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] }\n"
    )
    run = tmp_path / "run"
    r = cli_in_process(
        "fit", model, data, "--population", "20", "--generations", "30", "--out", run
    )
    assert r.returncode == 0, r.stderr
    rows = {
        row["parameter"]: row
        for row in csv.DictReader((run / "uncertainty.csv").read_text().splitlines())
    }
    anchors = [name for name in rows if ".anchor[" in name]
    assert len(anchors) == 3
    for name in anchors:
        assert rows[name]["determined"] == "no"
        assert rows[name]["std_error"] == "not determined"
        assert "does not change the residuals" in rows[name]["note"]
    assert all(rows[n]["determined"] == "yes" for n in rows if n not in anchors)
    assert "uncertainty: 9 of 12 parameters determined" in r.stdout
    report = tmp_path / "r.html"
    assert cli_in_process("report", run, "--out", report).returncode == 0
    assert "not determined" in report.read_text()


def test_masses_under_a_total_are_reported_in_kg_whatever_the_weights_scale():
    """Free masses under total_mass are genes w_i with m_i = total w_i / sum(w): the report
    gives m_i in kg with a standard error (the weights' common scale, which changes nothing,
    is not 'not determined'), the same at any scale of the weights."""
    from activebonds.identify.judge.uncertainty import estimate
    from activebonds.identify.problem import identification
    from activebonds.identify.settings import FitSettings
    from activebonds.model import loads_model
    from activebonds.simulation import simulate
    from test_gravity_masses import FREE_MASS, MASSES, chain

    data = simulate(loads_model(chain()), 60, 50.0)
    free_k = "{ value = 50.0, min = 5.0, max = 500.0 }"
    text = chain(f"total_mass = {sum(MASSES)}", masses=(FREE_MASS,) * 3, stiffness=(free_k,) * 3)
    model = loads_model(text)
    ident = identification(model, data, FitSettings())
    genome = np.log([*MASSES, 90.0, 40.0, 25.0])  # every gene is log-scaled here
    first = estimate(ident, FitSettings(), genome)
    scaled = estimate(ident, FitSettings(), genome + np.log(7.0) * np.array([1, 1, 1, 0, 0, 0]))
    names = [e.name for e in first.estimates]
    assert names[:3] == ["mass:p0.mass", "mass:p1.mass", "mass:p2.mass"]
    for a, b, m in zip(first.estimates[:3], scaled.estimates[:3], MASSES, strict=True):
        assert a.determined and a.value == pytest.approx(m, rel=1e-12)
        assert a.low < m < a.high
        assert b.value == pytest.approx(a.value, rel=1e-12)
        assert b.std_error == pytest.approx(a.std_error, rel=1e-6)
    assert first.directions == [] and first.rank == 6


def test_no_degrees_of_freedom_means_nothing_determined():
    jac = np.eye(3)
    est, rank, _, s2, dirs = from_jacobian(
        jac, np.zeros(3), ["a", "b", "c"], np.ones(3), np.ones(3), 0
    )
    assert not any(e.determined for e in est) and np.isnan(s2)
    assert dirs[0].startswith("no residual degrees of freedom")


def test_a_null_direction_in_the_start_states_alone_names_no_parameter():
    """Two parameters and a nuisance column no residual sees (a start state of masked frames):
    the parameters stay determined and the direction names no parameter."""
    rng = np.random.default_rng(5)
    jac = np.concatenate([rng.normal(size=(30, 2)), np.zeros((30, 1))], axis=1)
    est, rank, *_, dirs = from_jacobian(
        jac, rng.normal(size=30), ["a", "b"], np.ones(2), np.full(2, 10.0), 27
    )
    assert [e.determined for e in est] == [True, True]
    assert rank == 2 and dirs == ["a start state that no recorded frame sees (no parameter)"]


def test_a_jacobian_too_large_is_skipped_in_one_line(tmp_path, monkeypatch):
    """The fit completes; uncertainty.json says why there is no report; no CSV."""
    import activebonds.identify.judge.uncertainty as unc
    from activebonds.identify import fit
    from activebonds.simulation import simulate

    monkeypatch.setattr(unc, "MAX_JACOBIAN_BYTES", 1)
    model = load_model(TRIANGLE)
    result = fit(
        model,
        simulate(model, 40, 100.0),
        population=8,
        generations=3,
        out=tmp_path / "run",
        refine="none",
    )
    assert result.status == "completed"
    record = json.loads((tmp_path / "run" / "uncertainty.json").read_text())
    assert record["not_computed"].startswith("the Jacobian would take")
    assert not (tmp_path / "run" / "uncertainty.csv").exists()


def test_a_log_searched_parameter_has_its_interval_in_log_space_never_below_zero():
    """A positive stiffness of 1000 determined to +-60 % (se 600): in linear space its 95 %
    interval would go to -176; searched in log space, it is formed there: 1000 exp(+-1.96
    se / 1000), always positive, and held against the log range for 'not determined'."""
    rng = np.random.default_rng(5)
    x = rng.normal(size=(80, 1))
    resid = rng.normal(0.0, 1.0, 80)
    resid -= x[:, 0] * (x[:, 0] @ resid) / (x[:, 0] @ x[:, 0])  # at the optimum: J^T r = 0
    s = np.sqrt(resid @ resid / 79)
    x *= s / (600.0 * np.linalg.norm(x))  # se = s / |x| = 600
    args = (x, resid, ["bond[0].stiffness"], np.array([1000.0]))
    (linear,), *_ = from_jacobian(*args, np.array([1e4]), 79)
    assert linear.std_error == pytest.approx(600.0, rel=1e-9) and linear.low < 0
    wide = np.array([np.log(1e4 / 1.0)])  # search range 1 ... 10,000
    (logged,), *_ = from_jacobian(*args, wide, 79, log=np.array([True]))
    assert logged.determined and logged.std_error == pytest.approx(600.0, rel=1e-9)
    half = Z95 * 600.0 / 1000.0
    assert logged.low == pytest.approx(1000.0 * np.exp(-half), rel=1e-9) and logged.low > 0
    assert logged.high == pytest.approx(1000.0 * np.exp(half), rel=1e-9)
    assert "log space" in logged.note
    narrow = np.array([np.log(2.0)])  # search range 700 ... 1400: the data say less
    (undetermined,), *_ = from_jacobian(*args, narrow, 79, log=np.array([True]))
    assert not undetermined.determined


def test_every_log_searched_interval_of_a_noisy_fit_is_positive():
    """The estimate of a fit on noisy data, every gene log-scaled (masses under total_mass,
    stiffnesses): no interval reaches 0 or below."""
    from activebonds.identify.judge.uncertainty import estimate
    from activebonds.identify.problem import identification
    from activebonds.identify.settings import FitSettings
    from activebonds.model import loads_model
    from activebonds.simulation import simulate
    from test_gravity_masses import FREE_MASS, MASSES, chain

    data = simulate(loads_model(chain()), 40, 50.0)
    rng = np.random.default_rng(6)
    noisy = data.positions + rng.normal(0.0, 0.003, data.positions.shape)  # 3 mm
    data = type(data)(positions=noisy, mask=data.mask, markers=data.markers, rate=data.rate)
    free_k = "{ value = 50.0, min = 0.5, max = 5000.0 }"
    text = chain(f"total_mass = {sum(MASSES)}", masses=(FREE_MASS,) * 3, stiffness=(free_k,) * 3)
    ident = identification(loads_model(text), data, FitSettings())
    report = estimate(ident, FitSettings(), np.log([*MASSES, 90.0, 40.0, 25.0]))
    shown = [e for e in report.estimates if e.determined]
    assert len(shown) >= 3
    for e in shown:
        assert 0 < e.low < e.value < e.high
        assert np.log(e.high / e.value) == pytest.approx(np.log(e.value / e.low), rel=1e-9)


def test_the_intervals_say_where_they_cannot_be_trusted():
    from activebonds.identify.judge.uncertainty import warnings

    one_step = warnings("restart", 1, 1)
    assert len(one_step) == 2
    assert "one-step cost" in one_step[0] and "18 times too wide" in one_step[0]
    assert "--substeps 4" in one_step[1] and "64 % coverage" in one_step[1]
    assert warnings("shooting", 20, 4) == []
    assert warnings("restart", 10, 4) == []


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_fit_that_rejected_shooting_is_not_told_to_refit_with_shooting(tmp_path):
    """The triangle with a gravity nothing holds, fitted with --cost shooting: its best
    10-frame predictions lose to constant velocity, so the shooting stage is not kept and a
    one-step stage is refined in its place. The uncertainty warning says so, from the stage
    records, and does not send the user to --cost shooting."""
    from activebonds.identify import fit
    from activebonds.identify.judge.uncertainty import shooting_rejected, warnings
    from activebonds.model import loads_model
    from activebonds.simulation import simulate

    recording = simulate(load_model(TRIANGLE), 100, 100.0)
    falling = loads_model(
        TRIANGLE.read_text().replace("dimension = 3", "dimension = 3\ngravity = [0.0, 0.0, -9.81]")
    )
    result = fit(
        falling,
        recording,
        out=tmp_path / "run",
        population=8,
        generations=2,
        cost="shooting",
        horizon=(10,),
    )
    (stage,) = result.records["refine"]["stages"]
    assert (stage["cost"], stage["horizon"], stage["accepted"]) == ("restart", 1, True)
    why = stage["instead_of_shooting"]
    assert re.fullmatch(
        r"not shot: the model's best 10-frame predictions are no better than constant "
        r"velocity's \([\d.]+ vs [\d.]+ mm\)",
        why,
    )
    warned = result.records["uncertainty"]["warnings"]
    one_step = next(w for w in warned if w.startswith("these intervals come from"))
    assert one_step == (
        "these intervals come from the one-step cost: on noisy markers they can be up to 18 "
        "times too wide and blind to the bias noise puts in the damping (5-7 standard errors); "
        f"this fit tried shooting and did not keep it ({why}), so refitting with --cost "
        "shooting would not help: the model does not predict the recording over the shooting "
        "windows better than constant velocity; a model that does (see the free run's advice) "
        "comes first"
    )
    assert not any("refit with --cost shooting" in line for line in result.lines())
    assert f"uncertainty: warning: {one_step}" in result.lines()
    # a shooting stage rejected on its own objective, from a record (older ones lack the field)
    diverged = {"cost": "shooting", "horizon": 20, "accepted": False, "message": "it diverged"}
    assert shooting_rejected([diverged]) == ["horizon 20: it diverged"]
    assert warnings("restart", 1, 4, ["horizon 20: it diverged"])[0].endswith(
        "this fit tried shooting and did not keep it (horizon 20: it diverged), so refitting "
        "with --cost shooting alone would not give intervals that hold"
    )
    assert warnings("restart", 1, 4)[0].endswith(
        "refit with --cost shooting for intervals that hold"
    )


def test_a_model_that_misses_forces_is_told_its_intervals_do_not_describe_the_misfit():
    """The residuals a correct model leaves are the markers' noise through the cost (sqrt(6)
    sigma a coordinate one step ahead): at the true stiffnesses the fit's residual is that,
    within 6 %, and no misfit is said; at stiffnesses 10 % and 50 % off, on markers precise
    to 0.01 mm, the residuals are 3-40 times it and the warning says so."""
    from activebonds.identify.judge.uncertainty import MISFIT, estimate, misfit, noise_gain
    from activebonds.identify.problem import identification
    from activebonds.identify.settings import FitSettings
    from activebonds.identify.stages.uncertainty import marker_noise
    from activebonds.model import loads_model
    from activebonds.simulation import simulate
    from test_gravity_masses import STIFFNESS, chain

    assert noise_gain("restart", 1) == pytest.approx(np.sqrt(6.0))
    assert noise_gain("shooting", 10) == 1.0
    clean = simulate(loads_model(chain()), 40, 50.0)
    free_k = "{ value = 50.0, min = 0.5, max = 5000.0 }"
    model = loads_model(chain(stiffness=(free_k,) * 3))
    for sd, scale, said in ((5e-4, 1.0, False), (1e-5, 1.0, False), (1e-5, 0.9, True)):
        rng = np.random.default_rng(6)
        noisy = clean.positions + rng.normal(0.0, sd, clean.positions.shape)
        data = type(clean)(positions=noisy, mask=clean.mask, markers=clean.markers, rate=50.0)
        ident = identification(model, data, FitSettings())
        noise = marker_noise(ident.all_data)
        assert noise == pytest.approx(sd * 1000.0, rel=0.1)  # the fourth differences' estimate
        report = estimate(ident, FitSettings(), np.log(np.array(STIFFNESS) * scale))
        ratio = report.sigma_mm / (noise_gain("restart", 1) * noise)
        found = misfit(report.sigma_mm, noise, report.cost, 1)
        if said:
            assert ratio > MISFIT and "does not explain the recording" in found
            assert f"{ratio:.3g} times" in found
        else:
            assert 0.9 < ratio < 1.1 and found is None


def test_a_tall_jacobian_factored_a_block_at_a_time_gives_the_same_intervals(monkeypatch):
    """The SVD of a tall Jacobian through its triangular factor, built a block of rows at a
    time (uncertainty._triangle): the same singular values and right vectors as the SVD of
    the whole scaled Jacobian, so the same intervals, directions and rank."""
    from activebonds.identify.judge import uncertainty

    rng = np.random.default_rng(2)
    m, p = 3000, 12
    jac = rng.standard_normal((m, p)) * np.logspace(-3, 2, p)
    jac[:, 5] = jac[:, 4] * 2.0  # one direction not determined
    resid = 1e-3 * rng.standard_normal(m)
    names = [f"g{i}" for i in range(p)]
    values, spans = np.ones(p), np.full(p, 1e6)
    whole = uncertainty.from_jacobian(jac, resid, names, values, spans, m - p)
    norms, sv, vt, ok = uncertainty._decompose(jac)
    monkeypatch.setattr(uncertainty, "BLOCK_BYTES", 8 * p * 100)  # blocks of 100 rows: 30
    assert uncertainty._triangle(jac, norms).shape == (p, p)
    norms_b, sv_b, vt_b, ok_b = uncertainty._decompose(jac)
    np.testing.assert_allclose(sv_b, sv, rtol=1e-10, atol=1e-12 * sv[0])
    assert (ok_b == ok).all() and ok.sum() == p - 1
    np.testing.assert_allclose(np.abs(vt_b[ok_b] @ vt[ok].T), np.eye(p - 1), atol=1e-8)
    blocked = uncertainty.from_jacobian(jac, resid, names, values, spans, m - p)
    assert blocked[1:4] == pytest.approx(whole[1:4], rel=1e-9)
    for a, b in zip(blocked[0], whole[0], strict=True):
        assert a.determined == b.determined
        if a.determined:
            assert a.std_error == pytest.approx(b.std_error, rel=1e-8)
