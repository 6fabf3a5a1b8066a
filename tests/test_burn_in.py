"""Free runs after a burn-in (identify/judge/burn_in.py): the state estimated from the N
recorded frames before each start with the parameters held, then the simulation; zero force
the least-squares line through the same frames."""

from __future__ import annotations

import numpy as np
import pytest

from activebonds.identify.judge.burn_in import _line_runs, burn_in, burn_in_starts
from activebonds.identify.judge.metrics import free_run_from
from activebonds.model import load_model
from activebonds.simulation import simulate
from helpers import TRIANGLE


@pytest.fixture(scope="module")
def triangle():
    model = load_model(TRIANGLE)
    return model, simulate(model, 160, 100.0)


def test_the_true_model_after_a_burn_in_predicts_the_recording_exactly(triangle):
    """Noise-free frames of the model itself: the burn-in recovers the true state, so the
    run after it is the recording to rounding, at every frame ahead; zero force is not."""
    model, rec = triangle
    found = burn_in(model, rec.positions, rec.dt, 10, 30, starts=8)
    assert len(found.starts) == 8 and min(found.starts) >= 10
    assert max(found.model_mm) < 1e-9
    assert found.zero_force_mm[-1] > 10.0 and found.zero_force_mm[0] < found.zero_force_mm[-1]
    assert found.model_within == 30 and found.zero_force_within < 30
    assert found.lines()[0].startswith("free runs after a 10-frame burn-in (8 starts): 30 frames")


def test_a_burn_in_averages_the_noise_a_two_frame_start_carries(triangle):
    """0.5 mm of marker noise: the run from two recorded frames starts with their noise / dt
    in its velocity; after a 10-frame burn-in the true model's runs are several times closer
    to the noise-free motion 30 frames on."""
    model, rec = triangle
    rng = np.random.default_rng(1)
    noisy = rec.positions + rng.normal(0.0, 0.5e-3, rec.positions.shape)
    cut = noisy[:110]  # every start has its 30 frames ahead recorded
    found = burn_in(model, cut, rec.dt, 10, 30, starts=8)
    plain = []
    for s in found.starts:
        if s + 30 < len(cut):
            run = free_run_from(model, cut, rec.dt, s, 30)
            plain.append(np.sum((run[29] - cut[s + 30]) ** 2, axis=-1))
    plain_mm = 1000.0 * np.sqrt(np.mean(plain))
    assert found.model_mm[-1] < plain_mm / 3, (found.model_mm[-1], plain_mm)
    assert found.model_mm[-1] < found.zero_force_mm[-1] / 5


def test_zero_force_after_a_burn_in_is_the_line_through_the_window():
    """A body at constant velocity: the least-squares line is its motion, exactly; with the
    line's residual noise, the fitted line is the mean velocity's."""
    t = np.arange(12, dtype=np.float64)[:, None, None]
    x0, v = np.array([[0.1, 0.2, 0.3]]), np.array([[0.01, -0.02, 0.005]])
    window = (x0 + t * v)[None]  # [1, 12, 1, 3]
    runs = _line_runs(window, 5)
    expected = x0 + np.arange(12, 17, dtype=np.float64)[:, None, None] * v
    np.testing.assert_allclose(runs[0], expected, rtol=0, atol=1e-15)


def test_starts_need_a_complete_burn_in_window():
    x = np.zeros((40, 2, 3))
    x[15, 1] = np.nan
    starts = burn_in_starts(x, 5, 10, 100)
    assert starts[0] == 5 and all(not (s - 5 <= 15 <= s) for s in starts)
    assert len(burn_in_starts(x, 5, 10, 4)) == 4


def test_evaluate_burn_in_on_the_command_line(tmp_path):
    """`evaluate --burn-in 10`: the record's curve (100 frames ahead) and frames within 50 mm,
    the true model's at the rounding beside zero force's; a burn-in longer than the window is
    refused in one line naming --burn-in."""
    import json

    from activebonds.data import write_trajectory
    from helpers import cli_in_process

    data = tmp_path / "tri.csv"
    write_trajectory(simulate(load_model(TRIANGLE), 150, 100.0), data)
    done = cli_in_process("evaluate", TRIANGLE, data, "--burn-in", "10", "--json")
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout)["burn_in"]
    assert found["frames"] == 10 and len(found["model_mm"]) == 100
    finite = [x for x in found["model_mm"] if isinstance(x, float) and x == x]
    assert finite and max(finite) < 1e-6  # CSV's decimals: not to the bit
    assert found["zero_force_mm"][0] > 0 and found["model_within"] >= found["zero_force_within"]
    refused = cli_in_process("evaluate", TRIANGLE, data, "--frames", "0:8", "--burn-in", "10")
    assert refused.returncode == 2
    assert refused.stderr.strip().startswith("error: --burn-in: no start has 11 complete frames")


def test_the_mean_gait_after_a_burn_in_predicts_a_periodic_recording():
    """A noise-free periodic motion (a sum of harmonics per marker, feet lowest): the mean gait
    played from the phase and offset that fit the burn-in predicts the frames after it to the
    resampling's error, tens of frames on; shifted by a constant, the offset follows it."""
    from activebonds.report import gait as g

    period, n = 40.0, 400
    t = np.arange(n, dtype=np.float64)[:, None]
    rng = np.random.default_rng(3)
    amp, ph = rng.uniform(0.01, 0.05, (2, 4, 3)), rng.uniform(0, 2 * np.pi, (2, 4, 3))
    base = np.array([[0.0, 0.0, 0.02], [0.3, 0.0, 0.02], [0.0, 0.2, 1.0], [0.3, 0.2, 1.1]])
    x = base + sum(
        amp[h] * np.sin(2 * np.pi * (h + 1) * t[..., None] / period + ph[h]) for h in range(2)
    )
    ref = g.features(x, (0.0, 0.0, 1.0), [0, 1])
    assert ref.period_frames == pytest.approx(period, rel=0.01)
    runs = g.template_runs(x, ref, [60, 123, 250], 10, 60)
    for run, s in zip(runs, (60, 123, 250), strict=True):
        err = np.sqrt(np.sum((run - x[s + 1 : s + 61]) ** 2, axis=-1)) * 1000.0
        assert err.max() < 1.0, err.max()  # mm; the motion spans tens of mm
    moved = g.template_runs(x + [0.05, 0.0, 0.0], ref, [123], 10, 60)[0]
    assert np.abs(moved - x[124:184] - [0.05, 0.0, 0.0]).max() < 1e-3
