"""The silent phases say what happens (issue 15, item 9).

A fit's compilation, refinement and uncertainty, and the experiments' report, take seconds
to tens of seconds with nothing moving. On stderr they show a spinner when it is a terminal,
else one plain line each: "compiling the cost and the evolution strategy ...", "refining the
best model (Levenberg-Marquardt, 1 stage) ...", "estimating the uncertainty of the parameters
...", "writing the report ...". The plain compiling line comes once the initial population
was evaluated (a fit refused before, or failed there, stays one line), the spinner from the
start.
"""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from rich.console import Console
from typer.testing import CliRunner

from activebonds.cli.main import app
from activebonds.cli.progress import FitProgress
from reliability_runner import workspace

LINES = (
    "compiling the cost and the evolution strategy ...",
    "refining the best model (Levenberg-Marquardt, 1 stage) ...",
    "estimating the uncertainty of the parameters ...",
)


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_fit_not_on_a_terminal_prints_its_phases_on_stderr(tmp_path, tmp_path_factory):
    ws = workspace(tmp_path_factory)
    args = ["fit", ws["base"] / "triangle.toml", ws["base"] / "triangle.csv"]
    args += ["--out", tmp_path / "RUN", "--population", "10", "--generations", "10"]
    res = CliRunner().invoke(app, [str(a) for a in args + ["--refine", "lm"]])
    assert res.exit_code == 0, res.output
    err = res.stderr.splitlines()
    assert [line for line in err if line in LINES] == list(LINES), res.stderr
    assert not any(line in res.stdout for line in LINES)


def test_the_experiments_report_says_it_is_being_written(tmp_path, monkeypatch, capsys):
    import activebonds.experiments.report as report
    from activebonds.cli import experiments_cmd

    def write(summaries, folder):
        print("the report is written now", flush=True)
        return Path(folder) / "report.html"

    monkeypatch.setattr(report, "write_experiments_report", write)
    experiments_cmd._finish({}, tmp_path, 0.0)
    captured = capsys.readouterr()
    assert captured.err.splitlines()[0] == "writing the report ..."
    assert captured.out.splitlines()[0] == "the report is written now"


def test_a_terminal_gets_a_spinner_and_no_line_a_log_gets_the_line_only_when_work_starts():
    for terminal in (True, False):
        text = io.StringIO()
        console = Console(file=text, force_terminal=terminal, width=100)
        shown = FitProgress(10, Console(file=io.StringIO()), console)
        shown.begin("compiling the cost and the evolution strategy")
        assert (shown.spinner is not None) == terminal  # a log: nothing yet
        assert text.getvalue() == "" or terminal
        shown.status("refining the best model")
        assert (shown.spinner is not None) == terminal
        shown(5, 10, 1.0)  # the next chunk stops the spinner
        assert shown.spinner is None
        shown.close()
        if not terminal:
            assert text.getvalue() == "refining the best model ...\n"


def test_a_phase_s_detail_updates_its_line_and_a_log_gets_it_at_most_every_so_often(
    monkeypatch,
):
    import activebonds.cli.progress as progress

    phase = "refining the best model (Levenberg-Marquardt, 1 stage)"
    for terminal in (True, False):
        for every in (0.0, 1e9):  # a log: each detail, or none within the interval
            monkeypatch.setattr(progress, "DETAIL_SECONDS", every)
            text = io.StringIO()
            console = Console(file=text, force_terminal=terminal, width=200)
            shown = FitProgress(10, Console(file=io.StringIO()), console)
            shown.status(phase)
            first = shown.spinner
            for step in (2, 3):
                shown.status(f"{phase} - stage 1/1 (horizon 10), shooting: step {step}/100")
                assert shown.spinner is first  # the same line, updated (a terminal)
            assert shown.said.endswith("step 3/100")
            shown.status("measuring the fit beside its baselines")  # another phase: a new line
            assert (shown.spinner is not first) == terminal
            shown.close()
            if not terminal:
                lines = text.getvalue().splitlines()
                details = [line for line in lines if " - stage 1/1" in line]
                assert len(details) == (2 if every == 0.0 else 0), lines
                assert lines[0] == f"{phase} ..." and lines[-1].startswith("measuring")
