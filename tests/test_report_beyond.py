"""The report's verdict on the frames beyond the fit: one step and K frames ahead, overall and
per marker, with ``evaluate``'s numbers on those frames (the standing rule: every score beside
zero force's, saying whether it beats it); for ``auto``, its held-out evaluation's."""

from __future__ import annotations

import html
import re

import pytest

from activebonds.data import read_trajectory, write_trajectory
from activebonds.document import Marked
from activebonds.identify import fit
from activebonds.model import load_model, loads_model
from activebonds.report import predict_run, write_report
from activebonds.report.evaluate import evaluate
from activebonds.report.html import Beyond, errors_table
from activebonds.simulation import simulate
from helpers import TRIANGLE


@pytest.fixture(scope="module")
def stiff_run(tmp_path_factory):
    """A small fit of frames 0:60 of a 120-frame triangle recording, every stiffness fixed
    30 % too high (the model errs, more so several frames ahead than one)."""
    base = tmp_path_factory.mktemp("beyond")
    write_trajectory(simulate(load_model(TRIANGLE), 120, 60.0), base / "rec.csv")
    stiff = re.sub(
        r"stiffness = \{ value = ([\d.]+)[^}]*\}",
        lambda m: f"stiffness = {1.3 * float(m.group(1))!r}",
        TRIANGLE.read_text(),
    )
    run = base / "run"
    fit(
        loads_model(stiff),
        base / "rec.csv",
        out=run,
        frames=(0, 60),
        population=8,
        generations=3,
        refine="none",
    )
    return base, run


def _text(path) -> str:
    return html.unescape(path.read_text(encoding="utf-8"))


def test_the_report_says_evaluates_verdicts_beyond_the_fit_one_step_and_10_ahead(stiff_run):
    base, run = stiff_run
    report = write_report(run, base / "report.html", frames=120)
    found = evaluate(
        load_model(run / "best_model.toml"), read_trajectory(base / "rec.csv"), frames=(60, 120)
    )
    one, ahead = found.comparisons
    assert ahead.horizon == 10 and ahead.model_mm > 1.0  # millimetres: a number to compare
    text = _text(report)
    for c in (one, ahead):
        for line in c.lines("frames beyond the fit 60:120"):
            assert line in text, line
    assert "verdict, frames beyond the fit 60:120, 10 frames ahead: " in text
    # and per marker in the table, red where the model is not better than zero force
    table = errors_table(predict_run(run, 120)[0], beyond=Beyond((60, 120), (one, ahead)))
    assert table.columns[-2:] == ["10 ahead (beyond)", "zero force 10 ahead (beyond)"]
    for p, row in enumerate(table.rows):
        cell = row[-2]
        worse = ahead.per_marker[ahead.markers[p]].better is False
        value = cell.value if worse else cell
        assert value == pytest.approx(ahead.model_per_marker[p], rel=1e-12)
        assert row[-1] == pytest.approx(ahead.zero_force_per_marker[p], rel=1e-12)
        assert isinstance(cell, Marked) == worse
        # the one step beyond: evaluate's terms too (the verdict's numbers)
        assert row[5] == pytest.approx(one.model_per_marker[p], rel=1e-12) or (
            row[5].value == pytest.approx(one.model_per_marker[p], rel=1e-12)
        )
    assert "<th>10 ahead (beyond)</th>" in text


def test_an_evaluation_given_is_what_the_report_says(stiff_run):
    """``auto`` hands its held-out evaluation to the report: the report says those numbers
    (here a 5-frames-ahead one, which the report would not compute itself)."""
    base, run = stiff_run
    found = evaluate(
        load_model(run / "best_model.toml"),
        read_trajectory(base / "rec.csv"),
        frames=(60, 120),
        horizon=5,
    )
    given = Beyond.from_record(found.record())
    report = write_report(run, base / "given.html", frames=120, beyond=given)
    text = _text(report)
    assert found.comparisons[1].horizon == 5
    for c in found.comparisons:
        for line in c.lines("frames beyond the fit 60:120"):
            assert line in text, line
    assert "verdict, frames beyond the fit 60:120, 10 frames ahead" not in text
    assert "<th>5 ahead (beyond)</th>" in text


def test_the_baselines_say_the_summarys_figure_beyond_the_fit(stiff_run):
    """One run, one figure: the Baselines section's one step on the frames beyond is the
    summary's verdict's (evaluate's terms, a window of its own), not a second number predicted
    on from the fitted frames (a new user's report said 1.28 and 1.281 mm)."""
    from activebonds.identify.judge.verdict import Verdict

    base, run = stiff_run
    report = write_report(run, base / "one-figure.html", frames=120)
    found = evaluate(
        load_model(run / "best_model.toml"), read_trajectory(base / "rec.csv"), frames=(60, 120)
    )
    one = found.comparisons[0]
    said = Verdict(one.model_mm, one.zero_force_mm).text()
    text = _text(report)
    at = text.index('id="baselines"')
    assert said in text[:at] and said in text[at:]
