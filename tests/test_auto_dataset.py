"""``activebonds auto`` over a dataset (``auto/dataset.py``, ``cli/auto_dataset.py``): the
trials named by files, folders and globs; a trial a folder, a row a trial in summary.csv and
index.html, read back from the trial's folder; one unreadable file one row, the others
finished; rerun: the same rows; on Ray: the same numbers as one after another.

The recordings are made here: the triangle example simulated (no gravity, a free body) at
60 Hz and cut into sections of other lengths, one resampled to 30 Hz (every other frame),
written as TRC; and a file that is not a recording."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from activebonds import auto
from activebonds.auto import dataset
from activebonds.data import Trajectory, read_trajectory, write_trajectory
from activebonds.data.bundled import dataset as bundled
from activebonds.simulation import simulate_to_file

OPTIONS = auto.Options(gravity=False, population=8, generations=5, ahead=5)


def make_trials(folder: Path) -> list[Path]:
    """Three recordings of the triangle, sections of one simulation at 60 Hz: frames 0-199
    and 200-359 at 60 Hz (CSV), and frames 360-759 resampled to 30 Hz (every other frame,
    written as TRC); and one unreadable file."""
    folder.mkdir(parents=True, exist_ok=True)
    simulate_to_file(bundled("triangle.toml").path, 760, 60.0, folder / "sim.csv", None, 1,
                     "euler")  # fmt: skip
    sim = read_trajectory(folder / "sim.csv")

    def cut(rows, path: Path, rate: float) -> Path:
        write_trajectory(Trajectory(sim.positions[rows], sim.mask[rows], sim.markers, rate), path)
        return path

    paths = [
        cut(slice(0, 200), folder / "early.csv", 60.0),
        cut(slice(200, 360), folder / "late.csv", 60.0),
        cut(slice(360, 760, 2), folder / "slow.trc", 30.0),
    ]
    (folder / "sim.csv").unlink()
    broken = folder / "broken.csv"
    broken.write_text("not,a recording\n1,2\n", encoding="utf-8")
    return [*paths, broken]


# ----------------------------------------------------------------------------- the trials


def test_trials_are_named_from_files_folders_and_globs_each_once(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for p in ("a/walk.csv", "b/walk.csv", "a/trot.c3d", "a/notes.txt"):
        (tmp_path / p).write_text("x")
    got = dataset.trials([tmp_path / "a", str(tmp_path / "b" / "*.csv"), tmp_path / "a/walk.csv"])
    assert [(t.name, t.path.relative_to(tmp_path).as_posix()) for t in got] == [
        ("trot", "a/trot.c3d"),
        ("walk", "a/walk.csv"),
        ("walk-2", "b/walk.csv"),
    ]
    with pytest.raises(dataset.InputError, match="names no recording"):
        dataset.trials([str(tmp_path / "none*.csv")])


def test_a_row_is_read_from_the_trials_folder_and_the_page_links_its_report(tmp_path):
    folder = tmp_path / "early"
    folder.mkdir()
    (folder / "report.html").write_text("<html></html>")
    fit = {
        "run": "run-gait",
        "candidates": [
            {"candidate": "structure", "run": "run"},
            {"candidate": "gait", "run": "run-gait"},
        ],
    }
    (folder / "auto.json").write_text(json.dumps({"total_seconds": 12.34, "steps": {"fit": fit}}))
    verdict = {"verdict": "better"}
    held = {
        "model_name": "gait",
        "frames": [160, 200],
        "comparisons": [
            {"horizon": 1, "model_mm": 1.5, "zero_force_mm": 3.0, "verdict": verdict,
             "markers": ["A", "B", "C"], "worse_markers": ["C"]},
            {"horizon": 5, "model_mm": 10.0, "zero_force_mm": 40.0, "verdict": verdict,
             "markers": ["A", "B", "C"], "worse_markers": []},
        ],
    }  # fmt: skip
    (folder / "evaluation.json").write_text(json.dumps({"held_out": held}))
    trial = dataset.Trial("early", tmp_path / "early.csv")
    row = dataset.row(trial, folder, "done", "", 99.0)
    assert row["family"] == "gait" and row["held_out_frames"] == "160:200"
    assert (row["one_step_mm"], row["zero_force_one_step_mm"]) == (1.5, 3.0)
    assert (row["ahead"], row["ahead_mm"], row["zero_force_ahead_mm"]) == (5, 10.0, 40.0)
    assert row["markers_worse_one_step"] == 1 and row["markers"] == 3
    assert row["wall_s"] == 12.3 and row["report"] == "early/report.html"
    failed = dataset.row(dataset.Trial("bad", tmp_path / "bad.csv"), tmp_path / "bad", "error",
                         "bad.csv: not a recording", 0.5)  # fmt: skip
    dataset.write_summary(tmp_path, [row, failed])
    with open(tmp_path / "summary.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["trial"] for r in rows] == ["early", "bad"]
    assert (
        rows[0]["one_step_verdict"] == "better" and rows[1]["message"] == "bad.csv: not a recording"
    )
    page = (tmp_path / "index.html").read_text()
    assert '<a href="early/report.html">early</a>' in page
    assert "one step better at 1 of 2" in page and "bad.csv: not a recording" in page


@pytest.mark.parametrize(
    "args, option",
    [
        (["--workers", "0"], "--workers"),
        (["--address", "auto", "--sequential"], "--sequential"),
    ],
)
def test_bad_dataset_options_are_one_line_and_write_nothing(tmp_path, args, option):
    for name in ("a.csv", "b.csv"):
        (tmp_path / name).write_text("x")
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, "-m", "activebonds.cli", "auto", str(tmp_path / "a.csv"),
         str(tmp_path / "b.csv"), "--out", str(out), *args],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert option in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not out.exists()


# ----------------------------------------------------------------------------- whole datasets


def _rows(out: Path) -> list[dict]:
    with open(out / "summary.csv", newline="") as f:
        return list(csv.DictReader(f))


def _numbers(rows: list[dict]) -> list[tuple]:
    keys = ("trial", "status", "family", "one_step_mm", "zero_force_one_step_mm", "ahead_mm")
    return [tuple(r[k] for k in keys) for r in rows]


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_dataset_is_modelled_trial_by_trial_and_rerun_gives_the_same_rows(tmp_path):
    paths = make_trials(tmp_path / "data")
    out = tmp_path / "out"
    said = []
    rows = dataset.run_dataset(dataset.trials(paths), out, OPTIONS, False, said.append)
    assert [r["trial"] for r in rows] == ["early", "late", "slow", "broken"]
    done = [r for r in rows if r["status"] == "done"]
    assert len(done) == 3 and len(said) == 4
    for r in done:  # each score beside zero force's, the truth's family beats it one step
        assert r["one_step_mm"] < r["zero_force_one_step_mm"] and r["one_step_verdict"] == "better"
        assert (out / r["trial"] / "report.html").is_file()
    broken = rows[-1]
    assert broken["status"] == "error" and "broken.csv" in broken["message"]
    assert [(r["trial"], r["status"]) for r in _rows(out)] == [
        (r["trial"], r["status"]) for r in rows
    ]
    again = dataset.run_dataset(dataset.trials(paths), out, OPTIONS, False, lambda r: None)
    assert _numbers(again) == _numbers(rows)
    assert [r["wall_s"] for r in again[:3]] == [r["wall_s"] for r in rows[:3]]  # the trials' own


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_on_ray_the_trials_give_the_numbers_of_one_after_another(tmp_path):
    pytest.importorskip("ray")
    paths = make_trials(tmp_path / "data")[:2]
    env = dict(os.environ)
    results = {}
    for how in ("--sequential", "--workers=2"):
        out = tmp_path / how.strip("-").split("=")[0]
        proc = subprocess.run(
            [sys.executable, "-m", "activebonds.cli", "auto", *map(str, paths), "--out", str(out),
             "--no-gravity", "--population", "8", "--generations", "5", "--ahead", "5", how],
            capture_output=True, text=True, env=env, check=False,
        )  # fmt: skip
        assert proc.returncode == 0, proc.stderr[-2000:]
        results[how] = _numbers(_rows(out))
        assert "held out one step better than zero force in 2 of 2 trials" in proc.stdout
    assert results["--workers=2"] == results["--sequential"]
    assert np.all([r[1] == "done" for r in results["--sequential"]])


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_subjects_model_predicts_each_left_out_trial_beside_its_own_and_zero_force(tmp_path):
    """Leave-one-trial-out on three trials of the triangle (two at 60 Hz, one resampled to
    30 Hz): the model fitted on the other trials predicts each left-out trial's held-out
    frames one step better than zero force; the table holds its error beside the trial's own
    model's and zero force's on the same frames; the 30 Hz trial is left out of the fits
    (one line) and judged with the fit's step (two Euler substeps of 1/60 s)."""
    paths = make_trials(tmp_path / "data")[:3]
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, "-m", "activebonds.cli", "auto", *map(str, paths), "--out", str(out),
         "--no-gravity", "--population", "8", "--generations", "5", "--ahead", "5",
         "--sequential", "--subject"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.count("slow left out of the fit: 30 Hz, not 60 Hz") == 2
    with open(out / "subject.csv", newline="") as f:
        rows = {r["left_out"]: r for r in csv.DictReader(f)}
    assert set(rows) == {"early", "late", "slow"}
    assert rows["slow"]["fitted_on"] == "early late" and rows["early"]["fitted_on"] == "late"
    own = {r["trial"]: r for r in _rows(out)}
    for name, r in rows.items():
        assert r["subject_one_step_verdict"] == "better"
        subject, zero = float(r["subject_one_step_mm"]), float(r["zero_force_one_step_mm"])
        assert subject < 0.01 * zero  # the truth's family, fitted on other trials
        assert r["held_out_frames"] == own[name]["held_out_frames"]
        assert r["trial_model_one_step_mm"] == own[name]["one_step_mm"]
        assert r["zero_force_one_step_mm"] == own[name]["zero_force_one_step_mm"]
    assert "better than zero force in 3 of 3" in proc.stdout
