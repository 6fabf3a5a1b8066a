"""The command line's rough edges, each pinned: user text printed verbatim (no markup, no emoji
codes), ``--version`` and ``-h``, help whole at 80 columns, one meaning of ``--frames``, the
refinement's step limit as an option, and messages that name an option, never a function."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from typer.main import get_command

from activebonds import FitSettings, write_trajectory
from activebonds.cli.main import app
from activebonds.data.trajectory import Trajectory
from helpers import ROOT, TRIANGLE, both_ways_fresh_in_slow, cli

COMMANDS = dict(get_command(app).commands)


def _recording(path, markers=("x:100:", "B", "C"), frames=40):
    rng = np.random.default_rng(0)
    positions = rng.normal(size=(frames, len(markers), 3)) * 0.01 + np.arange(len(markers))[:, None]
    write_trajectory(
        Trajectory(positions, np.ones((frames, len(markers)), bool), tuple(markers), 60.0), path
    )
    return path


def test_a_marker_name_and_a_range_are_printed_verbatim(tmp_path):
    data = _recording(tmp_path / "rec.npz")
    proc = cli("info", data, "--markers", "x:100:,B")
    assert proc.returncode == 0, proc.stderr
    assert "x:100:" in proc.stdout and "💯" not in proc.stdout
    bad = cli("info", data, "--markers", "x:100:,nope")
    assert bad.returncode == 2
    assert "available: x:100:, B, C" in bad.stderr and "💯" not in bad.stderr
    rng = cli("scaffold", data, "--frames", "0:100:", "--out", tmp_path / "m.toml")
    assert rng.returncode == 2
    assert "'0:100:'" in rng.stderr and "💯" not in rng.stderr
    assert "[bold]" not in rng.stderr


def test_version_and_short_help():
    version = cli("--version")
    assert version.returncode == 0 and version.stdout.startswith("activebonds ")
    for args in (("-h",), ("fit", "-h"), ("simulate", "-h")):
        proc = cli(*args)
        assert proc.returncode == 0 and "Usage:" in proc.stdout, args


@pytest.mark.parametrize("command", [None, *COMMANDS])
def test_help_is_whole_at_80_columns(command):
    args = ("-h",) if command is None else (command, "-h")
    proc = subprocess.run(
        [sys.executable, "-m", "activebonds.cli", *args],
        env=dict(os.environ, COLUMNS="80"),
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    # "..." only after a name that takes several values (ARGS..., TRAJ...), never a cut
    text = re.sub(r"(\[ARGS\]|\{?traj\}?)\.\.\.", "", proc.stdout)
    assert "…" not in text and "..." not in text, text
    assert max(len(line) for line in proc.stdout.splitlines()) <= 80
    if command is not None:  # every option is listed
        for param in COMMANDS[command].params:
            if param.param_type_name == "option":
                assert param.opts[0] in proc.stdout, (command, param.opts[0])


def test_frames_is_a_start_stop_window_in_every_command():
    having = {
        name: p
        for name, command in COMMANDS.items()
        for p in command.params
        if "--frames" in p.opts
    }
    assert {"fit", "evaluate", "structure", "scaffold", "fill", "baselines"} <= set(having)
    for name, param in having.items():
        assert "START:STOP" in param.help, name
        assert param.bare_type() == "str", name  # parsed as START:STOP, never a count
    for name in ("simulate", "report"):  # their counts have another name
        opts = {o for p in COMMANDS[name].params for o in p.opts}
        assert "--n-frames" in opts and "--frames" not in opts


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_max_steps_bounds_every_refinement_stage(tmp_path):
    assert FitSettings().max_steps == 500
    assert "max_steps" not in FitSettings().job()  # runs from before the option resume
    assert FitSettings(max_steps=7).job()["max_steps"] == 7
    opts = {o for p in COMMANDS["fit"].params for o in p.opts}
    assert "--max-steps" in opts
    out = tmp_path / "run"
    proc = cli(
        *("fit", TRIANGLE, ROOT / "examples" / "triangle.csv", "--frames", "0:40"),
        *("--cost", "restart", "--generations", "2", "--population", "8"),
        *("--max-steps", "1", "--out", out),
    )
    assert proc.returncode == 0, proc.stderr
    stages = json.loads((out / "refine.json").read_text())["stages"]
    assert stages and all(s["steps"] <= 1 for s in stages)
    limited = [s for s in stages if "step limit (1)" in s["message"]]
    assert limited, stages
    assert "fit --max-steps" in proc.stdout


@pytest.mark.parametrize(*both_ways_fresh_in_slow())
def test_init_lsq_names_an_option_not_a_function(tmp_path, run):
    text = TRIANGLE.read_text().replace(
        "mass = 1.5\n", "mass = { value = 1.5, min = 1.0, max = 2.0 }\n", 1
    )
    assert text != TRIANGLE.read_text()
    model = tmp_path / "free_mass.toml"
    model.write_text(text)
    proc = run(
        *("fit", model, ROOT / "examples" / "triangle.csv", "--init", "lsq"),
        *("--generations", "2", "--population", "8", "--out", tmp_path / "run"),
    )
    assert proc.returncode == 2
    assert "equation_error_fit" not in proc.stderr
    assert "--init lsq" in proc.stderr and "free masses" in proc.stderr
