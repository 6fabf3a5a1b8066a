"""Where a free run starts: the model file's initial state, or a recording's first two frames.

A model without initial positions used to start every particle at the origin, so its bonds had
zero length and the run diverged with advice about stiffness. It is now refused before any
computation, naming the particles and the two ways to give a start; and the ``--from`` start
is checked against a known truth: a run started from the first two frames of the truth's own
free run retraces it.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from typer.testing import CliRunner

from activebonds import load_model, read_trajectory, simulate, write_trajectory
from activebonds.errors import InputError
from activebonds.model.io import loads_model
from helpers import TRIANGLE


def _without_start(text: str) -> str:
    return "\n".join(
        line for line in text.splitlines() if not line.startswith(("position", "velocity"))
    )


def _invoke(*args):
    from activebonds.cli.main import app

    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "300"})


def test_a_model_without_positions_is_refused_with_the_ways_to_start(tmp_path):
    model = tmp_path / "nopos.toml"
    model.write_text(_without_start(TRIANGLE.read_text()))
    out = tmp_path / "x.csv"
    res = _invoke("simulate", model, "--n-frames", "10", "--rate", "60", "--out", out)
    assert res.exit_code == 2, res.output
    lines = [line for line in res.output.splitlines() if line.strip()]
    assert len(lines) == 1, res.output
    line = lines[0]
    assert line.startswith(f"error: {model}: the model has no initial state"), line
    assert "3 of 3 particles have no position ('A', 'B', 'C')" in line
    assert "position = [...]" in line and "--from TRAJ" in line
    assert not re.search(r"stiffness|substeps", line)
    assert not out.exists()

    # the Python API says the same, and names start=
    with pytest.raises(InputError, match=r"no initial state.*start=trajectory"):
        simulate(loads_model(model.read_text()), 10, 60.0)


def test_one_particle_without_a_position_is_named(tmp_path):
    text = TRIANGLE.read_text().replace("position = [0.55, 0.0, 0.05]\n", "", 1)
    with pytest.raises(InputError, match=r"1 of 3 particles have no position \('B'\)"):
        simulate(loads_model(text), 10, 60.0)


def test_from_a_recording_retraces_the_truth(tmp_path):
    """The triangle's own free run, given to a model without positions through --from,
    is retraced: same first two frames, then the same run (semi-implicit Euler carries the
    start velocity (x1 - x0) / dt exactly)."""
    truth = simulate(load_model(TRIANGLE), 60, 60.0)
    recording = tmp_path / "truth.csv"
    write_trajectory(truth, recording)
    model = tmp_path / "nopos.toml"
    model.write_text(_without_start(TRIANGLE.read_text()))
    out = tmp_path / "again.csv"
    res = _invoke(
        "simulate", model, "--n-frames", "60", "--rate", "60", "--from", recording, "--out", out
    )
    assert res.exit_code == 0, res.output
    again = read_trajectory(out)
    stored = read_trajectory(recording)
    assert again.n_frames == 60
    assert np.abs(again.positions - stored.positions).max() < 1e-6  # metres, after CSV rounding
    # and it moved: the comparison is not of two still pictures
    assert np.ptp(stored.positions[:, 0, 1]) > 0.01
