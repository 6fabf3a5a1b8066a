"""The verdict on every score: better than zero force by X %, or worse (the model does not
explain this motion), overall and per marker, one step and K frames ahead; the rule and the
words of one module (activebonds.identify.judge.verdict) wherever a model is scored."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from activebonds.data import Trajectory, write_trajectory
from activebonds.identify.judge.ahead import compare, comparisons
from activebonds.identify.judge.metrics import window_metrics
from activebonds.identify.judge.predictions import zero_force_ahead
from activebonds.identify.judge.verdict import (
    EXPLAINS_NOT,
    MARGIN_PCT,
    Comparison,
    verdict,
)
from activebonds.model import load_model, loads_model
from activebonds.simulation import simulate
from helpers import TRIANGLE, cli_in_process

FRAMES = 100
RATE = 100.0


def _text(stiffness=None, damping=None) -> str:
    """The triangle's file with every stiffness (damping) fixed at the given value."""
    text = TRIANGLE.read_text()
    if stiffness is not None:
        text = re.sub(r"stiffness = \{[^}]*\}", f"stiffness = {stiffness}", text)
    if damping is not None:
        text = re.sub(r"damping = \{[^}]*\}", f"damping = {damping}", text)
    return text


@pytest.fixture(scope="module")
def recording():
    return simulate(load_model(TRIANGLE), FRAMES, RATE)


# ----------------------------------------------------------------------------- the rule


def test_the_words_and_the_rule():
    worse = verdict(1.842, 1.811)
    assert worse.better is False and worse.word == "worse"
    assert worse.text() == f"worse than zero force (1.842 vs 1.811 mm): {EXPLAINS_NOT}"
    assert worse.gain_pct == pytest.approx(100 * (1 - 1.842 / 1.811))
    better = verdict(1.59, 1.81)
    assert better.better is True and better.word == "better"
    assert better.text() == "better than zero force by 12.2 % (1.59 vs 1.81 mm)"
    tie = verdict(1.81 * (1 - MARGIN_PCT / 200), 1.81)  # better by half the margin: not
    assert tie.better is False and tie.word == "no better"
    assert tie.text().startswith("no better than zero force (") and EXPLAINS_NOT in tie.text()
    missing = verdict(float("nan"), 1.0)
    assert missing.better is None and missing.text().startswith("not judged")
    failed = verdict(float("inf"), 1.0)
    assert failed.better is False and failed.gain_pct == -np.inf
    assert verdict(None, 1.0).better is None
    d = worse.to_dict()
    assert d["better"] is False and d["verdict"] == "worse" and d["text"] == worse.text()


def test_per_marker_words_name_the_worse_markers():
    c = Comparison(
        0.9,
        1.0,
        horizon=1,
        markers=("Head", "Withers"),
        model_per_marker=(0.79, 0.5),
        zero_force_per_marker=(0.39, 1.2),
    )
    assert c.overall.better is True
    assert c.worse_markers() == ["Head"]
    assert c.markers_text() == (
        "not better than zero force at 1 of 2 markers: Head 0.79 vs 0.39 mm"
    )
    assert c.lines("held-out frames")[0].startswith("verdict, held-out frames, one step: better")
    assert Comparison.from_dict(json.loads(json.dumps(c.to_dict()))) == c
    k = Comparison(
        1.0, 2.0, horizon=10, markers=("A",), model_per_marker=(1.0,), zero_force_per_marker=(2.0,)
    )
    assert k.what == "10 frames ahead"
    assert k.markers_text() == "better than zero force at every marker (1)"


# ----------------------------------------------------------------------------- the numbers


def test_zero_force_k_ahead_matches_a_hand_computation(recording):
    """x_{s+K} = x_s + K (x_s - x_{s-1}) from every s with both frames recorded; a gap at
    frame 40 removes the starts that need it and the targets there."""
    x = np.array(recording.positions)
    mask = np.ones(x.shape[:2], bool)
    x[40, 1] = np.nan
    mask[40, 1] = False
    gappy = Trajectory(positions=x, mask=mask, markers=recording.markers, rate=RATE)
    k = 7
    sq = [[] for _ in range(3)]
    for s in range(1, FRAMES - k):
        if np.isnan(x[s - 1]).any() or np.isnan(x[s]).any():
            continue
        pred = x[s] + k * (x[s] - x[s - 1])
        for p in range(3):
            if not np.isnan(x[s + k, p]).any():
                sq[p].append(np.sum((pred[p] - x[s + k, p]) ** 2))
    per = [np.sqrt(np.mean(v)) * 1000 for v in sq]
    overall = np.sqrt(np.mean(np.concatenate(sq))) * 1000
    c = compare(load_model(TRIANGLE), gappy, k)
    assert c.zero_force_per_marker == pytest.approx(per, rel=1e-12)
    assert c.zero_force_mm == pytest.approx(overall, rel=1e-12)
    assert c.terms == sum(len(v) for v in sq)
    assert np.isnan(zero_force_ahead(x, k)[: k + 1]).all()


def test_the_true_model_beats_zero_force_everywhere(recording):
    one, ahead = comparisons(load_model(TRIANGLE), recording, 10)
    assert (one.horizon, ahead.horizon) == (1, 10)
    for c in (one, ahead):
        assert c.model_mm < 1e-6 and c.zero_force_mm > 0.1
        assert c.overall.better and c.overall.gain_pct > 99.99
        assert c.worse_markers() == []
    # one step: the same terms and number as fit's summary (window_metrics)
    found = window_metrics(load_model(TRIANGLE), recording, 1, "euler")
    assert one.zero_force_mm == pytest.approx(found["zero_force"].one_step_rms_mm, rel=1e-12)
    assert one.model_mm == pytest.approx(found["model"].one_step_rms_mm, abs=1e-9)


def test_a_model_without_forces_is_no_better_and_a_wrong_one_is_worse(recording):
    none = loads_model(_text(stiffness=0.0, damping=0.0))  # every force zero: zero force
    for c in comparisons(none, recording, 10):
        assert c.model_mm == pytest.approx(c.zero_force_mm, rel=1e-9)
        assert c.overall.better is False and c.overall.word == "no better"
        assert EXPLAINS_NOT in c.overall.text()
        assert c.worse_markers() == ["A", "B", "C"]
    # damping alone (worse at one step; 10 frames ahead it slows the bonds' stretching a
    # little, which happens to help); too stiff (worse at both)
    damped = comparisons(loads_model(_text(stiffness=0.0)), recording, 10)[:1]
    stiff = comparisons(loads_model(_text(stiffness=900.0)), recording, 10)
    for c in damped + stiff:
        assert c.model_mm > c.zero_force_mm
        assert c.overall.better is False and c.overall.word == "worse"
        assert c.overall.text().startswith("worse than zero force (")
        assert c.worse_markers()


# ----------------------------------------------------------------------------- where shown


def test_evaluate_says_the_verdict_overall_per_marker_and_k_ahead(recording, tmp_path):
    path = tmp_path / "rec.csv"
    write_trajectory(recording, path)
    wrong = tmp_path / "wrong.toml"
    wrong.write_text(_text(stiffness=900.0))
    res = cli_in_process("evaluate", wrong, path, "--horizon", "5")
    assert res.returncode == 0, res.stderr
    assert "5-frame-ahead RMS (mm)" in res.stdout
    assert f"verdict, frames 0:{FRAMES}, one step: worse than zero force (" in res.stdout
    assert f"verdict, frames 0:{FRAMES}, 5 frames ahead: worse than zero force (" in res.stdout
    assert "per marker: not better than zero force at" in res.stdout
    res = cli_in_process("evaluate", TRIANGLE, path, "--json")
    data = json.loads(res.stdout)
    one, ahead = data["comparisons"]
    assert ahead["horizon"] == 10 and one["verdict"]["better"] and ahead["verdict"]["better"]
    assert one["zero_force_mm"] == pytest.approx(data["zero_force"]["one_step_rms_mm"])
    bad = cli_in_process("evaluate", TRIANGLE, path, "--horizon", "0")
    assert bad.returncode == 2 and "--horizon" in bad.stderr


def test_a_fit_says_its_verdict_on_fitted_and_held_out_frames(recording, tmp_path):
    from activebonds.identify import fit

    result = fit(
        TRIANGLE,
        recording.window(0, FRAMES),
        out=tmp_path / "run",
        population=16,
        generations=3,
        validate=(60, None),
        frames=(0, 60),
        refine="none",
    )
    found = result.comparisons
    assert set(found) == {"fitted", "held_out"}
    assert [c.horizon for c in found["fitted"]] == [1, 10]
    assert result.verdict == found["held_out"][0].overall
    lines = result.lines()
    assert any(line.startswith("verdict, fitted frames, one step: ") for line in lines)
    assert any(
        line.startswith("verdict, held-out validation frames 60:100, 10 frames ahead")
        for line in lines
    )
    # the numbers: zero force on the fitted frames, one step, as the baselines stage measured
    assert found["fitted"][0].zero_force_mm == pytest.approx(
        result.records["baselines"]["fitted"]["zero_force"]["one_step_rms_mm"], rel=1e-12
    )
    # what holds the model, kept for the free run's advice (report and resume read it back)
    # (the triangle's damped ringing repeats no period: no drive is advised, test_newcomer_messages)
    held = {"gravity": False, "contacts": 0, "anchors": 0, "drive": False, "repeats": False}
    assert result.records["baselines"]["holds"] == held
    from activebonds.sweep.summary import row

    columns = row(tmp_path / "run")
    assert columns["fitted_one_step_verdict"] in ("better", "worse", "no better")
    assert "held_out_10_ahead_gain_pct" in columns


def test_a_free_run_that_falls_away_gets_one_line_of_advice(recording):
    """The triangle with gravity and nothing to hold it: its free run falls metres in a
    second; evaluate says so once, with what to add: ground contacts first (it has none). The
    true model gets no advice."""
    from activebonds.identify.judge.verdict import free_run_advice
    from activebonds.report.evaluate import evaluate

    falling = loads_model(
        TRIANGLE.read_text().replace("dimension = 3", "dimension = 3\ngravity = [0.0, 0.0, -9.81]")
    )
    found = evaluate(falling, recording)
    assert found.model.free_run_rms_mm > 1000.0
    held = {"gravity": True, "contacts": 0, "anchors": 0, "drive": False, "repeats": False}
    assert found.holds == held
    advice = [line for line in found.lines() if line.startswith("advice:")]
    far = f"ends {found.model.free_run_rms_mm / 1000:.3g} m (RMS) from the recording"
    assert advice == [
        f"advice: the free run {far}: the model has gravity and no ground contacts, so the "
        "body falls; add ground contacts (activebonds scaffold writes them) or anchors (unary "
        "springs)"
    ]  # no rhythmic drive: the recording repeats no period
    assert found.record()["holds"] == found.holds
    assert not any(
        line.startswith("advice:") for line in evaluate(load_model(TRIANGLE), recording).lines()
    )
    assert free_run_advice(999.0) is None and "non-finite" in free_run_advice(float("inf"))


CONTACT = """
[[bond]]
kind = "contact"
particles = ["A"]
normal = [0.0, 0.0, 1.0]
height = -50.0
stiffness = 1000.0
damping = 10.0
friction = 0.8
"""


def test_a_model_with_contacts_that_diverges_is_not_told_to_add_contacts(recording):
    """The falling triangle with a ground contact too far below to catch it: the advice names
    what it lacks (anchors; a drive only where the recording repeats itself), stiffer contacts
    and a shorter horizon, never contacts to add."""
    from activebonds.identify.judge.verdict import free_run_advice
    from activebonds.report.evaluate import evaluate

    text = TRIANGLE.read_text().replace(
        "dimension = 3", "dimension = 3\ngravity = [0.0, 0.0, -9.81]"
    )
    found = evaluate(loads_model(text + CONTACT), recording)
    held = {"gravity": True, "contacts": 1, "anchors": 0, "drive": False, "repeats": False}
    assert found.holds == held
    advice = [line for line in found.lines() if line.startswith("advice:")]
    far = f"ends {found.model.free_run_rms_mm / 1000:.3g} m (RMS) from the recording"
    assert advice == [
        f"advice: the free run {far} although the model has 1 ground contact: they do not "
        "hold it on the recording's path; add anchors (unary springs), make the contacts "
        "stiffer (raise their stiffness and its bounds), or judge it over a shorter horizon "
        "(evaluate --horizon, the frames-ahead comparison) than a free run of the whole window"
    ]
    assert "add ground contacts" not in advice[0]
    # anchors and a drive present: only what it lacks is named
    both = {"gravity": True, "contacts": 4, "anchors": 1, "drive": True}
    assert free_run_advice(2000.0, both) == (
        "advice: the free run ends 2 m (RMS) from the recording although the model has 4 "
        "ground contacts: they do not hold it on the recording's path; make the contacts "
        "stiffer (raise their stiffness and its bounds), or judge it over a shorter horizon "
        "(evaluate --horizon, the frames-ahead comparison) than a free run of the whole window"
    )
    bare = {"gravity": False, "contacts": 0, "anchors": 0, "drive": False}
    assert free_run_advice(2000.0, bare) == (
        "advice: the free run ends 2 m (RMS) from the recording: nothing holds the body or "
        "drives it; add anchors (unary springs) or a rhythmic drive ([drive] and neural bonds)"
    )


def test_the_report_marks_the_markers_worse_than_zero_force_in_red(recording):
    """The per-particle table of a report: a too-stiff triangle is worse than zero force at
    every marker one step ahead (fitted frames and beyond): those cells are marked and
    rendered red; the true model's are not."""
    from activebonds.document import Marked
    from activebonds.report.html import _table, errors_table
    from activebonds.report.predict import predict

    stiff = predict(loads_model(_text(stiffness=900.0)), recording, fit_frames=60)
    table = errors_table(stiff)
    assert list(table.columns[2:4]) == ["one-step (fit)", "zero force (fit)"]
    marked = [row[0] for row in table.rows if isinstance(row[2], Marked)]
    assert marked == ["A", "B", "C"]
    a = table.rows[0]
    assert a[2].value > a[3] and "worse than zero force" in a[2].why
    assert isinstance(a[5], Marked) and a[5].value > a[6]  # beyond the fitted frames
    html = _table(table)
    assert html.count('class="num worse"') == 6 and "red: not better than zero force" in html
    assert "worse" not in _table(
        errors_table(predict(load_model(TRIANGLE), recording, fit_frames=60))
    )
