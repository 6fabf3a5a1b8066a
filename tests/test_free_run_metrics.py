"""Free run as a metric: frames within the threshold (censoring, gaps), the zero-force
predictor, the true model, and ``fit --validate`` through the command line and the report."""

from __future__ import annotations

import json

import numpy as np
import pytest

from activebonds.data import Trajectory, read_trajectory, write_trajectory
from activebonds.identify.judge.baselines import zero_force_rms_mm
from activebonds.identify.judge.metrics import (
    THRESHOLD_MM,
    censored_median,
    frames_within,
    free_run_metrics,
    max_error_mm,
    start_frames,
    validation_data,
    validation_record,
    zero_force_metrics,
)
from activebonds.identify.judge.predictions import free_run
from activebonds.identify.settings import FitSettings
from activebonds.model import load_model, loads_model
from activebonds.report import predict, write_report
from activebonds.simulation import simulate
from helpers import TRIANGLE, cli_in_process


def _drift(errors_mm, n_markers=2):
    """Recorded zeros and a prediction whose marker 1 is ``errors_mm`` away (x axis)."""
    n = len(errors_mm)
    rec = np.zeros((n, n_markers, 3))
    pred = np.zeros_like(rec)
    pred[:, 1, 0] = np.asarray(errors_mm, np.float64) / 1000.0
    return pred, rec


# ----------------------------------------------------------------------------- the counts


def test_frames_within_counts_the_frames_before_the_first_one_off():
    pred, rec = _drift([10, 20, 30, 40, 50, 60, 10, 70])
    assert THRESHOLD_MM == 50.0
    # 50 mm is not "more than 50 mm": frames 0-4 are within, frame 5 is off
    assert frames_within(pred, rec) == (5, False)
    assert frames_within(pred, rec, threshold_mm=25) == (2, False)
    assert frames_within(pred, rec, threshold_mm=5) == (0, False)


def test_a_run_that_never_gets_off_is_censored_at_its_length():
    pred, rec = _drift([1, 2, 3, 4, 5, 6])
    assert frames_within(pred, rec) == (6, True)
    assert frames_within(pred, rec, threshold_mm=100) == (6, True)
    assert frames_within(pred[:0], rec[:0]) == (0, True)


def test_gaps_are_no_evidence_and_the_worst_recorded_marker_counts():
    pred, rec = _drift([10, 20, 90, 30, 60])
    pred[:, 0, 1] = 0.040  # marker 0 is 40 mm off everywhere
    rec[2] = np.nan  # frame 2 (90 mm off) was not recorded at all: the count goes on
    assert max_error_mm(pred, rec)[:2].tolist() == pytest.approx([40, 40])
    assert np.isnan(max_error_mm(pred, rec)[2])
    assert frames_within(pred, rec) == (4, False)
    rec[4, 1] = np.nan  # marker 1 unseen at frame 4: marker 0 (40 mm) is the worst seen
    assert frames_within(pred, rec) == (5, True)
    pred[3, 0] = np.nan  # a recorded marker without a finite prediction is off
    assert frames_within(pred, rec) == (3, False)
    pred[3, 0] = 1e300  # too far to square: off too
    assert frames_within(pred, rec) == (3, False)


def test_the_median_is_a_lower_bound_when_a_censored_run_is_at_or_below_it():
    assert censored_median([3, 4, 20], [False, False, True]) == (4.0, False)
    assert censored_median([3, 10, 10], [False, False, True]) == (10.0, True)
    assert censored_median([3, 2, 9, 7], [True, False, False, False]) == (5.0, True)
    assert censored_median([5, 7], [False, False]) == (6.0, False)
    value, cens = censored_median([], [])
    assert np.isnan(value) and not cens


def test_starts_need_two_complete_frames_and_half_the_window_to_go():
    x = np.zeros((21, 2, 3))
    assert start_frames(x, 100) == list(range(1, 11))
    assert start_frames(x, 5) == [1, 3, 5, 8, 10]  # evenly spread, rounded
    x[4, 1] = np.nan  # frames 4 and 5 cannot start a run
    assert 4 not in start_frames(x, 100) and 5 not in start_frames(x, 100)
    assert start_frames(x, [0, 3, 4, 5, 6, 19, 20, 99]) == [3, 6, 19]


# ----------------------------------------------------------------------------- predictors


def test_the_zero_force_predictor_never_leaves_a_uniformly_moving_particle():
    n = 60
    t = np.arange(n)[:, None, None]
    x = np.array([[0.1, -0.2, 0.3]]) + t * np.array([[0.05, 0.02, -0.03]])  # 3 m/s
    traj = Trajectory(x, np.ones((n, 1), bool), ("p",), rate=60.0)
    m = zero_force_metrics(traj)
    assert len(m.starts) == 10 and max(m.starts) <= n // 2
    assert m.frames_within == tuple(n - 1 - s for s in m.starts)  # to the window's end
    assert all(m.censored) and m.median_censored
    assert m.frames_within[0] == n - 2
    assert m.one_step_rms_mm < 1e-9 and m.free_run_rms_mm < 1e-9
    assert m.frames_text().startswith(">= ")


def test_the_zero_force_numbers_are_the_baseline_s(triangle):
    _, traj = triangle
    m = zero_force_metrics(traj)
    assert m.one_step_rms_mm == pytest.approx(
        zero_force_rms_mm(traj.positions, traj.mask, traj.dt), rel=1e-12
    )
    assert not any(m.censored)  # the triangle's oscillation leaves a straight line
    s = 20
    x = traj.positions
    line = x[s] + np.arange(1, len(x) - s)[:, None, None] * (x[s] - x[s - 1])
    assert zero_force_metrics(traj, starts=[s]).frames_within == (
        frames_within(line, x[s + 1 :])[0],
    )


@pytest.fixture(scope="module")
def triangle():
    model = load_model(TRIANGLE)
    return model, simulate(model, 120, 60.0)


def test_the_true_model_runs_free_to_the_window_end(triangle):
    model, traj = triangle
    m = free_run_metrics(model, traj)
    n = traj.n_frames
    assert m.n_frames == n and len(m.starts) == 10
    assert m.one_step_rms_mm < 1e-9 and m.free_run_rms_mm < 1e-6
    assert m.frames_within == tuple(n - 1 - s for s in m.starts) and all(m.censored)
    assert m.frames_within[0] == n - 2 and m.median_censored


def test_a_wrong_model_gets_off_and_agrees_with_the_prediction(triangle):
    model, traj = triangle
    stiff = model.spec.model_copy(
        update={"bond": [b.model_copy(update={"stiffness": 400.0}) for b in model.spec.bond]}
    )
    from activebonds.model import build

    wrong = build(stiff)
    m = free_run_metrics(wrong, traj)
    pred = predict(wrong, traj)
    # no gap: every particle has as many terms, so the RMS is the mean of the per-particle
    assert m.free_run_rms_mm == pytest.approx(np.sqrt(np.mean(pred.free_run_rms_mm**2)))
    assert m.one_step_rms_mm == pytest.approx(np.sqrt(np.mean(pred.one_step_rms_mm**2)))
    assert m.free_run_rms_mm > 10 and not all(m.censored) and not m.median_censored
    # a start's run is the free run from that start's two frames (a time-free model)
    s = m.starts[3]
    xs, _ = free_run(wrong, traj.positions[s - 1 :], traj.dt)
    assert m.frames_within[3] == frames_within(xs[2:], traj.positions[s + 1 :])[0]
    # a time-free model does not see the time origin
    later = free_run_metrics(wrong, traj, offset=37)
    assert later.frames_within == m.frames_within and later.starts == m.starts
    assert later.free_run_rms_mm == pytest.approx(m.free_run_rms_mm, rel=1e-12)
    assert later.one_step_rms_mm == pytest.approx(m.one_step_rms_mm, rel=1e-12)
    low = free_run_metrics(wrong, traj, threshold_mm=1.0)
    assert all(a <= b for a, b in zip(low.frames_within, m.frames_within, strict=True))
    assert low.threshold_mm == 1.0


def test_validation_windows_are_checked(triangle):
    model, traj = triangle
    settings = FitSettings(frames=(0, 60))
    for frames, text in (
        ((50, 100), "overlap the fitted frames 0:60"),
        ((60, 130), "out of range"),
        ((100, 105), "at least 10 needed"),
    ):
        with pytest.raises(Exception, match=text):
            validation_data(model, traj, settings, frames)
    gappy = traj.with_positions(np.where(np.arange(120)[:, None, None] % 2, traj.positions, np.nan))
    with pytest.raises(Exception, match="free-run starts"):
        validation_data(model, gappy, settings, (60, 120))
    assert validation_data(model, traj, settings, (60, None)).n_frames == 60


# ----------------------------------------------------------------------------- --validate


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_fit_validate_end_to_end(tmp_path, triangle):
    model, traj = triangle
    data = tmp_path / "triangle.csv"
    write_trajectory(simulate(model, 200, 60.0), data)
    run = tmp_path / "RUN"
    common = (
        "fit", TRIANGLE, data, "--frames", "0:100", "--population", "20",
        "--generations", "20", "--seed", "3",
    )  # fmt: skip

    refused = cli_in_process(*common, "--out", run, "--validate", "90:200")
    assert refused.returncode == 2
    assert refused.stderr.strip().count("\n") == 0 and "overlap" in refused.stderr
    assert not run.exists()
    short = cli_in_process(*common, "--out", run, "--validate", "100:104")
    assert short.returncode == 2 and "at least 10" in short.stderr and not run.exists()

    proc = cli_in_process(*common, "--out", run, "--validate", "100:200")
    assert proc.returncode == 0, proc.stderr
    stored = json.loads((run / "validation.json").read_text())
    assert stored["frames"] == [100, 200] and stored["time_offset_frames"] == 100

    best = load_model(run / "best_model.toml")
    settings = FitSettings(frames=(0, 100), population=20, generations=20, seed=3)
    recording = read_trajectory(data)
    held = validation_data(best, recording, settings, (100, 200))
    direct = validation_record(best, held, settings, (100, 200))
    assert stored == json.loads(json.dumps(direct))
    m = stored["model"]
    assert len(m["starts"]) == 10 and m["threshold_mm"] == 50.0
    assert f"free-run RMS {float(m['free_run_rms_mm']):.4g} mm" in proc.stdout
    assert "validation frames 100:200" in proc.stdout and "fitted frames" in proc.stdout

    html = write_report(run).read_text()
    assert "<caption>Free run." in html
    assert "validation 100:200" in html and "fitted 0:100" in html
    assert html.count("<td>zero force</td>") == 2


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_a_report_without_validation_has_the_fitted_rows(tmp_path):
    model = loads_model(TRIANGLE.read_text())
    from activebonds.identify import fit

    data = simulate(model, 40, 60.0)
    fit(model, data, out=tmp_path / "r", population=8, generations=2, refine="none")
    html = write_report(tmp_path / "r").read_text()
    assert (
        "<caption>Free run." in html
        and "validation" not in html.split("<caption>Free run.")[1].split("</table>")[0]
    )
