"""The report's figure of each frame's one-step error, the model's beside zero force's."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from activebonds.identify.judge.baselines import zero_force_predictions
from activebonds.report import plots


def test_each_frame_s_error_is_the_rms_over_the_markers_and_the_figure_plots_it():
    """Two markers, one missing in a frame: a frame's error is the RMS over the markers
    scored (3-D distances 3 and 4 mm: 3.536 mm); the figure draws the model's and zero
    force's errors and marks in red the frames where the model's is above."""
    rng = np.random.default_rng(3)
    recorded = rng.normal(0.0, 0.01, (12, 2, 3))
    one_step = recorded.copy()
    one_step[:, 0, 0] += 0.003  # 3 mm off on marker 0
    one_step[:, 1, 1] += 0.004  # 4 mm off on marker 1
    one_step[5, 1] = np.nan  # marker 1 not predicted at frame 5
    errors = plots.frame_errors_mm(one_step, recorded)
    assert errors[5] == pytest.approx(3.0)
    assert errors[0] == pytest.approx(np.sqrt((9.0 + 16.0) / 2.0))
    assert np.isnan(plots.frame_errors_mm(np.full((2, 2, 3), np.nan), recorded[:2])).all()

    pred = SimpleNamespace(
        recorded=recorded, one_step=one_step, n_frames=12, fit_frames=8, extended=True, dt=0.01
    )
    zero, _ = zero_force_predictions(recorded, 1)
    fig = plots.one_step_errors_figure(pred, zero, first_frame=100)
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    frames = np.arange(100, 112)
    np.testing.assert_array_equal(lines["model"].get_xdata(), frames)
    np.testing.assert_allclose(lines["model"].get_ydata(), errors)
    np.testing.assert_allclose(
        lines["zero force"].get_ydata(), plots.frame_errors_mm(zero, recorded), equal_nan=True
    )
    zero_mm = plots.frame_errors_mm(zero, recorded)
    worse = np.isfinite(zero_mm) & (errors > zero_mm)
    np.testing.assert_array_equal(lines["model worse than zero force"].get_xdata(), frames[worse])
