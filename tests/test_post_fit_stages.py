"""Post-fit stages behind one protocol (identify/stages): a stage defined here, in the test
file, runs through fit, resume, report and sweep without editing the package; and a fit
from Python and from the command line with the same settings write the same run directory.
"""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from activebonds.cli.main import app
from activebonds.document import Section
from activebonds.identify import fit, stages
from activebonds.identify.stages import Outcome
from helpers import EXAMPLES, TRIANGLE

DATA = EXAMPLES / "triangle.csv"
SHORT = ["--frames", "0:30", "--population", "10", "--generations", "6"]


class ToyStage:
    """Sums the best model's free parameters: a record, a printed line, a report section, a
    sweep column."""

    name = "toy"
    state = None

    def doing(self, fit) -> str:
        return "adding up the genome"

    def applies(self, fit) -> bool:
        return fit.completed

    def run(self, fit, saved, arrays) -> Outcome:
        runs = 1 if saved is None else saved["runs"] + 1  # resumable: it sees its own record
        natural = fit.ident.model.layout.natural(fit.genome)
        return Outcome({"sum": float(np.sum(natural)), "runs": runs})

    def lines(self, record: dict) -> list[str]:
        return [f"toy: genome sum {record['sum']!r} (run {record['runs']})"]

    def sections(self, record: dict, report) -> list[Section]:
        return [Section("Toy stage", text=[f"genome sum {record['sum']!r}"], anchor="toy")]

    def columns(self, record: dict) -> dict:
        return {"toy_sum": record["sum"]}


def _invoke(*args):
    res = CliRunner().invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res.stdout


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_stage_from_outside_the_package_runs_through_fit_resume_report_and_sweep(tmp_path):
    run = tmp_path / "run"
    with stages.registered(ToyStage()):
        assert stages.names()[-1] == "toy"
        printed = _invoke("fit", TRIANGLE, DATA, "--out", run, *SHORT, "--refine", "none")
        record = json.loads((run / "toy.json").read_text())
        values = [g.value for g in _best_genes(run)]
        assert record == {"runs": 1, "sum": pytest.approx(float(np.sum(values)), rel=1e-12)}
        assert f"toy: genome sum {record['sum']!r} (run 1)" in printed

        # resume (extending the run): the stage runs again from what it saved
        printed = _invoke("resume", run, "--generations", "8")
        again = json.loads((run / "toy.json").read_text())
        assert again["runs"] == 2 and "(run 2)" in printed

        # the report renders the record (and computes nothing for it)
        _invoke("report", run)
        html = (run / "report.html").read_text()
        assert 'id="toy"' in html and f"genome sum {again['sum']!r}" in html

        # the sweep tabulates its column
        manifest = tmp_path / "sweep.toml"
        manifest.write_text(
            f'[defaults]\nmodel = "{TRIANGLE}"\ndata = "{DATA}"\nframes = "0:30"\n'
            'generations = 4\npopulation = 10\nrefine = "none"\n\n'
            '[[fit]]\nname = "toy"\nseed = [1, 2]\n'
        )
        _invoke("sweep", manifest, "--out", tmp_path / "sweep", "--sequential")
        with open(tmp_path / "sweep" / "summary.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        for row in rows:
            toy = json.loads((tmp_path / "sweep" / row["name"] / "toy.json").read_text())
            assert float(row["toy_sum"]) == toy["sum"]
    assert "toy" not in stages.names()  # registered inside the with block only


def _best_genes(run: Path):
    from activebonds.model import load_model

    return load_model(run / "best_model.toml").layout.genes


# wall-clock fields: when a run was made and how long its parts took, nothing of the result
CLOCK = {"created", "command", "updated", "wall_seconds", "seconds"}


def _without_clock(value):
    if isinstance(value, dict):
        return {k: _without_clock(v) for k, v in value.items() if k not in CLOCK}
    if isinstance(value, list):
        return [_without_clock(v) for v in value]
    return value


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_python_and_the_command_line_write_the_same_run_directory(tmp_path):
    """Same settings, defaults included (refine lm, validation frames; the cost named, the
    command line's default being auto): the same history, best model and stage records,
    file by file."""
    shell, python = tmp_path / "shell", tmp_path / "python"
    args = ["--frames", "0:40", "--population", "10", "--generations", "8", "--seed", "3"]
    args += ["--cost", "restart"]
    printed = _invoke("fit", TRIANGLE, DATA, "--out", shell, *args, "--validate", "60:100")
    result = fit(
        TRIANGLE,
        DATA,
        out=python,
        frames=(0, 40),
        population=10,
        generations=8,
        seed=3,
        validate=(60, 100),
    )
    names = sorted(p.name for p in shell.iterdir() if p.is_file())
    assert names == sorted(p.name for p in python.iterdir() if p.is_file())
    for name in ("refine", "baselines", "uncertainty", "validation"):
        assert f"{name}.json" in names
        stored = json.loads((python / f"{name}.json").read_text())
        assert _without_clock(stored) == _without_clock(
            json.loads(json.dumps(result.records[name]))
        )
    for name in names:
        a, b = (shell / name).read_bytes(), (python / name).read_bytes()
        if name.endswith(".json"):
            a, b = _without_clock(json.loads(a)), _without_clock(json.loads(b))
        elif name.endswith(".npz"):
            with np.load(shell / name) as za, np.load(python / name) as zb:
                assert sorted(za.files) == sorted(zb.files)
                for k in za.files:
                    if k != "record":  # the record is compared as JSON above
                        np.testing.assert_array_equal(za[k], zb[k])
            continue
        assert a == b, f"{name} differs"
    # the command line printed the stages' lines, the numbers of the records
    zero = re.search(r"zero-force baseline on the same frames ([0-9.]+) mm", printed)
    assert zero and float(zero.group(1)) == float(
        f"{result.records['baselines']['zero_force_rms_mm']:.4g}"
    )
    assert "validation frames 60:100" in " ".join(printed.split())
