"""``activebonds evaluate``: any model scored on any recording, with the numbers of fit's
summary (one-step RMS, free-run RMS, frames within 50 mm) from the same functions, the
zero-force baseline, per particle; a table, JSON, and one-line refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from activebonds.cli.main import app
from activebonds.data import Trajectory, read_trajectory, write_trajectory
from activebonds.errors import InputError
from activebonds.identify.judge.metrics import free_run_from, window_metrics
from activebonds.model import load_model, loads_model
from activebonds.report.evaluate import evaluate
from activebonds.report.predict import predict
from activebonds.simulation import simulate
from helpers import TRIANGLE

FRAMES = 100
RATE = 100.0


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The triangle, a recording of it, and a recording of a stiffer, differently damped
    triangle (another model)."""
    d = tmp_path_factory.mktemp("evaluate")
    model = load_model(TRIANGLE)
    own = d / "own.csv"
    write_trajectory(simulate(model, FRAMES, RATE), own)
    text = TRIANGLE.read_text()
    other_text = text.replace("value = 40.0", "value = 90.0").replace(
        "value = 1.0,", "value = 3.0,"
    )
    assert other_text != text
    other = d / "other.csv"
    other_traj = simulate(loads_model(other_text), FRAMES, RATE)
    write_trajectory(other_traj, other)
    return model, own, other, other_traj


def _zero_force_per_particle(rec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One-step and free-run (from frames 0 and 1) RMS (mm) per particle of the
    constant-velocity predictor, written out here from its definition."""
    one = 2 * rec[1:-1] - rec[:-2]
    one_rms = np.sqrt(np.mean(np.sum((one - rec[2:]) ** 2, axis=-1), axis=0)) * 1000
    k = np.arange(1, rec.shape[0] - 1)[:, None, None]
    run = rec[1] + k * (rec[1] - rec[0])
    run_rms = np.sqrt(np.mean(np.sum((run - rec[2:]) ** 2, axis=-1), axis=0)) * 1000
    return one_rms, run_rms


def test_a_model_on_its_own_simulation_predicts_it_exactly(files):
    model, own, _, _ = files
    found = evaluate(model, read_trajectory(own))
    m, z = found.model, found.zero_force
    assert m.one_step_rms_mm < 1e-6 and m.free_run_rms_mm < 1e-6
    assert m.median_censored and all(m.censored)  # no free run ever gets off
    assert m.frames_within == tuple(FRAMES - s - 1 for s in m.starts)
    assert z.one_step_rms_mm > 0.01 and z.free_run_rms_mm > 1.0
    assert found.frames == (0, FRAMES) and found.markers == ("A", "B", "C")
    assert [p.particle for p in found.particles] == ["A", "B", "C"]
    for p in found.particles:
        assert p.one_step_rms_mm < 1e-6 and p.free_run_rms_mm < 1e-6
        assert p.zero_force_one_step_rms_mm > 0 and p.zero_force_free_run_rms_mm > 0


def test_on_another_models_recording_the_numbers_are_the_metrics_functions(files):
    model, _, _, other = files
    found = evaluate(model, other)
    direct = window_metrics(model, other, 1, "euler")
    assert found.model == direct["model"]
    assert found.zero_force == direct["zero_force"]
    assert found.model.one_step_rms_mm > 1e-3  # a different model: not exact
    pred = predict(model, other)
    zero_one, zero_run = _zero_force_per_particle(np.asarray(other.positions))
    for i, p in enumerate(found.particles):
        assert p.one_step_rms_mm == pytest.approx(pred.one_step_rms_mm[i], rel=1e-12)
        assert p.free_run_rms_mm == pytest.approx(pred.free_run_rms_mm[i], rel=1e-12)
        assert p.zero_force_one_step_rms_mm == pytest.approx(zero_one[i], rel=1e-12)
        assert p.zero_force_free_run_rms_mm == pytest.approx(zero_run[i], rel=1e-12)
    # every particle has as many terms here: the overall RMS is the particles' quadratic mean
    for attr, overall in (
        ("one_step_rms_mm", found.model.one_step_rms_mm),
        ("free_run_rms_mm", found.model.free_run_rms_mm),
        ("zero_force_one_step_rms_mm", found.zero_force.one_step_rms_mm),
        ("zero_force_free_run_rms_mm", found.zero_force.free_run_rms_mm),
    ):
        per = np.array([getattr(p, attr) for p in found.particles])
        assert np.sqrt(np.mean(per**2)) == pytest.approx(overall, rel=1e-9), attr


def test_a_window_and_markers_in_another_order(files):
    model, _, _, other = files
    found = evaluate(model, other, markers=("C", "A", "B"), frames=(20, 70))
    assert found.frames == (20, 70) and found.markers == ("C", "A", "B")
    assert [(p.particle, p.marker) for p in found.particles] == [("A", "C"), ("B", "A"), ("C", "B")]
    window = other.select(["C", "A", "B"]).window(20, 70)
    assert found.model == window_metrics(model, window, 1, "euler")["model"]


def test_a_gap_weights_each_particle_by_its_terms(files):
    """Marker B missing at frames 40-44: per-particle RMS over different term counts; their
    count-weighted quadratic mean is the overall one-step RMS of the metrics."""
    model, _, _, other = files
    pos = np.array(other.positions)
    pos[40:45, 1] = np.nan
    gappy = Trajectory(
        positions=pos, mask=np.isfinite(pos).all(axis=-1), markers=other.markers, rate=other.rate
    )
    found = evaluate(model, gappy)
    complete = np.isfinite(pos).all(axis=(1, 2))
    inputs = np.zeros(len(pos), bool)
    inputs[2:] = complete[1:-1] & complete[:-2]
    terms = (inputs[:, None] & np.isfinite(pos).all(axis=-1)).sum(axis=0)
    assert terms[0] > terms[1]
    for attr, overall in (
        ("one_step_rms_mm", found.model.one_step_rms_mm),
        ("zero_force_one_step_rms_mm", found.zero_force.one_step_rms_mm),
    ):
        per = np.array([getattr(p, attr) for p in found.particles])
        weighted = np.sqrt(np.sum(terms * per**2) / terms.sum())
        assert weighted == pytest.approx(overall, rel=1e-9), attr


def test_the_body_markers_alone_count_their_own_frames_within(files):
    """``body``: the same free runs from the same starts, off once one of the named markers
    is (here at 0.5 mm, as the triangle's runs on another triangle's recording stay within
    50 mm); counted by hand from the runs, for the model and for zero force."""
    model, _, _, other = files
    rec = np.asarray(other.positions, np.float64)
    found = evaluate(model, other, body=["B"], threshold_mm=0.5)
    assert found.body_markers == ("B",)
    body, every = found.body["model"], found.model
    assert body.starts == every.starts

    def by_hand(run, s):
        err = np.linalg.norm(run - rec[s + 1 :, 1], axis=-1) * 1000.0
        off = np.flatnonzero(err > 0.5)
        return int(off[0]) if off.size else len(err)

    runs = {
        s: free_run_from(model, rec, other.dt, s, FRAMES - 2)[: FRAMES - s - 1] for s in body.starts
    }
    assert list(body.frames_within) == [by_hand(runs[s][:, 1], s) for s in body.starts]
    k = np.arange(1, FRAMES)[:, None]
    zero = {s: rec[s, 1] + k[: FRAMES - s - 1] * (rec[s, 1] - rec[s - 1, 1]) for s in body.starts}
    assert list(found.body["zero_force"].frames_within) == [
        by_hand(zero[s], s) for s in body.starts
    ]
    # one marker's errors can only end a run later than every marker's
    assert all(b >= e for b, e in zip(body.frames_within, every.frames_within, strict=True))
    assert any(b > e for b, e in zip(body.frames_within, every.frames_within, strict=True))
    assert body.one_step_rms_mm == pytest.approx(found.particles[1].one_step_rms_mm, rel=1e-12)
    with pytest.raises(InputError, match="--body"):
        evaluate(model, other, body=["Z"])


# ----------------------------------------------------------------------------- command line


def _run(*args):
    return CliRunner().invoke(app, ["evaluate", *map(str, args)])


def test_the_command_prints_a_table_and_json(files):
    model, own, other, other_traj = files
    res = _run(TRIANGLE, other)
    assert res.exit_code == 0, res.output
    text = res.output
    for words in ("one-step RMS (mm)", "free-run RMS (mm)", "frames within 50 mm", "zero force"):
        assert words in text
    assert "per particle" in text
    found = evaluate(model, read_trajectory(other))  # as the command reads it
    assert f"{found.model.one_step_rms_mm:.6g}" in text
    for p in found.particles:
        assert f"{p.zero_force_one_step_rms_mm:.6g}" in text

    res = _run(TRIANGLE, other, "--json")
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    assert set(record) == {
        "model_file",
        "model_name",
        "trajectory",
        "frames",
        "markers",
        "substeps",
        "integrator",
        "model",
        "zero_force",
        "particles",
        "comparisons",  # the verdicts, one step and 10 frames ahead (test_verdict.py)
        "holds",  # what holds the model, for the free run's advice (test_verdict.py)
    }
    assert record["model_file"] == str(TRIANGLE) and record["frames"] == [0, FRAMES]
    assert record["model"] == found.model.to_dict()
    assert record["zero_force"] == found.zero_force.to_dict()
    assert [p["particle"] for p in record["particles"]] == ["A", "B", "C"]
    first = record["particles"][0]
    assert set(first) == {"particle", "marker", "one_step_rms_mm", "free_run_rms_mm"}
    assert first["one_step_rms_mm"] == {
        "model": found.particles[0].one_step_rms_mm,
        "zero_force": found.particles[0].zero_force_one_step_rms_mm,
    }
    assert set(first["free_run_rms_mm"]) == {"model", "zero_force"}

    res = _run(TRIANGLE, other, "--body", "A,C")
    assert res.exit_code == 0, res.output
    assert "frames within 50 mm, A, C (median of 10 starts)" in res.output
    res = _run(TRIANGLE, other, "--json", "--body", "C,A")
    body = json.loads(res.stdout)["body"]
    direct = evaluate(model, read_trajectory(other), body=["A", "C"]).body
    assert body["markers"] == ["A", "C"] and body["model"] == direct["model"].to_dict()
    assert body["zero_force"] == direct["zero_force"].to_dict()

    res = _run(TRIANGLE, own, "--json", "--frames", "10:60", "--markers", "A,B,C")
    record = json.loads(res.stdout)
    assert record["frames"] == [10, 60] and float(record["model"]["one_step_rms_mm"]) < 1e-6


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (("missing.toml", "OWN"), "no such model file"),
        (("MODEL", "missing.csv"), "missing.csv"),
        (("MODEL", "OWN", "--markers", "A,B"), "--markers: 2 markers given"),
        (("MODEL", "OWN", "--markers", "A,B,Z"), "marker 'Z' not found"),
        (("MODEL", "OWN", "--frames", "x:y"), "--frames"),
        (("MODEL", "OWN", "--frames", "50:40"), "--frames"),
        (("MODEL", "OWN", "--frames", "0:999"), "out of range"),
        (("MODEL", "OWN", "--integrator", "rk4"), "--integrator"),
        (("MODEL", "OWN", "--substeps", "0"), "--substeps"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(files, tmp_path, args, words):
    _, own, _, _ = files
    swap = {"MODEL": TRIANGLE, "OWN": own, "missing.toml": tmp_path / "missing.toml"}
    swap["missing.csv"] = tmp_path / "missing.csv"
    res = _run(*(swap.get(a, a) for a in args))
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), res.output
    assert words in lines[0]


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_runs_best_model_is_scored_with_the_runs_integration(files, tmp_path):
    """``evaluate RUN/best_model.toml`` without --substeps and --integrator scores the model
    as the fit (and its report) did: with the run's substeps and integrator, named in the
    title; given options still win."""
    from activebonds.identify import fit

    model, own, other, _ = files
    run = tmp_path / "run"
    fit(
        TRIANGLE,
        own,
        out=run,
        population=8,
        generations=2,
        refine="none",
        substeps=3,
        integrator="verlet",
    )
    best = run / "best_model.toml"
    res = _run(best, other, "--json")
    assert res.exit_code == 0, res.output
    record = json.loads(res.stdout)
    assert (record["substeps"], record["integrator"]) == (3, "verlet")
    found = evaluate(load_model(best), read_trajectory(other), substeps=3, integrator="verlet")
    assert record["model"] == found.model.to_dict()
    table = _run(best, other)
    assert "(3 verlet substeps per frame)" in table.output
    given = json.loads(_run(best, other, "--json", "--substeps", "1").stdout)
    assert (given["substeps"], given["integrator"]) == (1, "verlet")
    plain = json.loads(_run(TRIANGLE, other, "--json").stdout)
    assert (plain["substeps"], plain["integrator"]) == (1, "euler")
