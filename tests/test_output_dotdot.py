"""Output paths with ``..`` (a researcher's analysis/ -> ../results): every command that
writes accepts them and writes where the system follows them, as ``fill`` and ``scaffold``
always did; every other check stays (an existing folder is no new run directory)."""

from __future__ import annotations

import numpy as np
import pytest

from activebonds.data import Trajectory, read_trajectory, write_trajectory
from activebonds.model import load_model
from activebonds.simulation import simulate
from helpers import EXAMPLES, cli_in_process


@pytest.fixture
def layout(tmp_path):
    """tmp/analysis (where the user works) and tmp/results (where the outputs go), a
    60-frame triangle recording and its gappy copy."""
    (tmp_path / "analysis").mkdir()
    (tmp_path / "results").mkdir()
    traj = simulate(load_model(EXAMPLES / "triangle.toml"), n_frames=60, rate=60.0)
    write_trajectory(traj, tmp_path / "triangle.csv")
    gappy = traj.positions.copy()
    gappy[20:24, 1] = np.nan
    mask = np.isfinite(gappy).all(axis=-1)
    write_trajectory(Trajectory(gappy, mask, traj.markers, traj.rate), tmp_path / "gappy.csv")
    return tmp_path


def up(tmp_path, name: str) -> str:
    """``tmp/analysis/../results/NAME``: a path through ``..``."""
    return str(tmp_path / "analysis" / ".." / "results" / name)


def test_simulate_export_scaffold_fill_write_through_dotdot(layout):
    model = EXAMPLES / "triangle.toml"
    res = cli_in_process(
        "simulate", model, "--n-frames", "5", "--rate", "60", "--out", up(layout, "s.csv")
    )
    assert res.returncode == 0, res.stderr
    assert read_trajectory(layout / "results" / "s.csv").n_frames == 5
    res = cli_in_process("export", model, "--format", "mjcf", "--out", up(layout, "m.xml"))
    assert res.returncode == 0, res.stderr
    assert "<mujoco" in (layout / "results" / "m.xml").read_text()
    res = cli_in_process("scaffold", layout / "triangle.csv", "--out", up(layout, "s.toml"))
    assert res.returncode == 0, res.stderr
    assert "[[bond]]" in (layout / "results" / "s.toml").read_text()
    res = cli_in_process(
        "fill", model, layout / "gappy.csv", "--method", "linear", "--out", up(layout, "f.csv")
    )
    assert res.returncode == 0, res.stderr
    filled = read_trajectory(layout / "results" / "f.csv")
    assert filled.n_frames == 60 and np.isfinite(filled.positions[20:24, 1]).all()
    assert sorted(p.name for p in (layout / "analysis").iterdir()) == []


def test_fit_writes_its_run_through_dotdot_and_refuses_an_existing_folder(layout):
    model, data = EXAMPLES / "triangle.toml", layout / "triangle.csv"
    fit = ("fit", model, data, "--generations", "2", "--population", "8", "--refine", "none")
    res = cli_in_process(*fit, "--out", up(layout, "run"))
    assert res.returncode == 0, res.stderr
    assert (layout / "results" / "run" / "run.json").is_file()
    assert (layout / "results" / "run" / "best_model.toml").is_file()
    # a second fit there needs --overwrite, as without '..'
    res = cli_in_process(*fit, "--out", up(layout, "run"))
    assert res.returncode == 2 and "--overwrite" in res.stderr
    # 'analysis/..' is the existing folder itself, never a new run directory (its name is
    # the folder's, not '..'), even with --overwrite: nothing there changes
    before = sorted(p.name for p in layout.iterdir())
    res = cli_in_process(*fit, "--out", str(layout / "analysis" / ".."), "--overwrite")
    assert res.returncode == 2 and "not a run directory" in res.stderr, res.stderr
    assert sorted(p.name for p in layout.iterdir()) == before


def test_experiments_take_an_output_folder_through_dotdot(layout, monkeypatch):
    from activebonds.cli import experiments_cmd

    seen = []

    def runner(names, scale, seeds, out_dir):
        seen.append(out_dir)
        return []

    monkeypatch.setattr(experiments_cmd, "_progress_runner", runner)
    monkeypatch.setattr(experiments_cmd, "_finish", lambda summaries, out_dir, started: None)
    res = cli_in_process("reproduce", "synthetic", "--scale", "tiny", "--out", up(layout, "exp"))
    assert res.returncode == 0, res.stderr
    res = cli_in_process("demo", "--out", up(layout, "demo"))
    assert res.returncode == 0, res.stderr
    assert seen == [(layout / "results" / "exp").resolve(), (layout / "results" / "demo").resolve()]
