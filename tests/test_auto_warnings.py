"""No library warning reaches the user on ``activebonds auto``'s path: auto run with its
numpy-warning filter off and every warning an error, on recordings made here — the bundled
walk made gait-lab-like (``scripts/gaitlab_recording.py``: resampled, marker noise, camera
dropouts and long occlusions, so no frame may hold every marker) and a simulated triangle."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import pytest

from activebonds import auto
from activebonds.auto.folder import Options
from activebonds.data.bundled import dataset
from activebonds.data.readers import read_trajectory
from activebonds.data.writers import write_trajectory

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import gaitlab_recording  # noqa: E402


def _auto_raising(path, out, **options):
    lines = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        outcome = auto.run(
            path,
            out,
            Options(**options),
            say=lines.append,
            verbose=False,
            hide_numpy_warnings=False,
        )
        verdicts = outcome.verdict_lines()
    return verdicts, lines


@pytest.mark.slow
def test_a_gappy_gait_lab_recording_raises_no_warning(tmp_path):
    walk = read_trajectory(dataset("human-walk").path)
    lab = gaitlab_recording.gaitlab(walk, rate=100.0, noise_mm=0.3, seed=2, markers=12)
    assert lab.mask.all(axis=1).mean() < 0.9 and not lab.mask.all()
    path = tmp_path / "lab.c3d"
    write_trajectory(lab, path)
    verdicts, lines = _auto_raising(path, tmp_path / "out", population=8, generations=5)
    assert any("zero force" in line for line in verdicts)
    assert (tmp_path / "out" / "report.html").exists()


def test_a_simulated_body_raises_no_warning(tmp_path):
    from activebonds.simulation import simulate_to_file

    path = tmp_path / "triangle.csv"
    simulate_to_file(dataset("triangle.toml").path, 200, 60.0, path, None, 1, "euler")
    verdicts, _ = _auto_raising(path, tmp_path / "out", gravity=False, population=8, generations=5)
    assert any("zero force" in line for line in verdicts)
    assert (tmp_path / "out" / "report.html").exists()
