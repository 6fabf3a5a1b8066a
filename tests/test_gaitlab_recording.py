"""scripts/gaitlab_recording.py: the gait-lab-like recording of the bundled human walk."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from activebonds.data.bundled import dataset
from activebonds.data.readers import read_trajectory

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import gaitlab_recording  # noqa: E402


@pytest.fixture(scope="module")
def walk():
    return read_trajectory(dataset("human-walk").path)


def _spline(walk, times, marker):
    return CubicSpline(walk.times, walk.positions[:, marker], axis=0)(times)


def test_rate_frames_presence_and_exact_samples(walk):
    traj = gaitlab_recording.gaitlab(walk, rate=250.0, noise_mm=0.0, seed=1)
    assert traj.rate == 250.0
    assert traj.n_frames == 626  # 150 frames at 60 Hz = 2.5 s, at 250 Hz: 625 steps
    assert traj.n_markers == 41
    complete = traj.mask.all(axis=1).mean()
    assert 0.30 <= complete <= 0.40
    assert 0.8 <= traj.mask.mean() <= 0.95  # most samples are kept all the same
    # a third of the markers hidden for ~30 % of the trial (edges jittered by <= 0.08 s)
    assert 12 <= np.sum(traj.mask.mean(axis=0) < 0.8) <= 16
    for m in (0, 17, 40):
        want = _spline(walk, traj.times, m)
        seen = traj.mask[:, m]
        np.testing.assert_array_equal(traj.positions[seen, m], want[seen])
        assert np.all(np.isnan(traj.positions[~seen, m]))


def test_noise_and_subset(walk):
    traj = gaitlab_recording.gaitlab(walk, rate=200.0, noise_mm=0.3, seed=4, markers=10)
    keep = gaitlab_recording.kept_markers(41, 10)
    assert list(keep) == [0, 4, 9, 13, 18, 22, 27, 31, 36, 40]
    assert traj.markers == tuple(walk.markers[i] for i in keep)
    assert traj.n_frames == 501
    errors = []
    for j, m in enumerate(keep):
        seen = traj.mask[:, j]
        errors.append(traj.positions[seen, j] - _spline(walk, traj.times[seen], m))
    sd_mm = np.concatenate(errors).std() * 1000.0
    assert sd_mm == pytest.approx(0.3, rel=0.05)


def test_written_files_read_back(walk, tmp_path, capsys):
    assert (
        gaitlab_recording.main(["--rate", "120", "--noise-mm", "0", "--out", str(tmp_path / "r")])
        == 0
    )
    made = gaitlab_recording.gaitlab(walk, rate=120.0, noise_mm=0.0, seed=1)
    for suffix, tol in ((".trc", 1e-12), (".c3d", 1e-4)):  # c3d: float32 millimetres
        back = read_trajectory(tmp_path / f"r{suffix}")
        assert back.rate == 120.0 and back.n_frames == made.n_frames
        np.testing.assert_array_equal(back.mask, made.mask)
        np.testing.assert_allclose(back.positions[back.mask], made.positions[made.mask], atol=tol)
    assert "frames with every marker present" in capsys.readouterr().out
