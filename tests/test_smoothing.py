"""Savitzky-Golay smoothing of the cost's restart states (``fit --smooth N``) and the marker
noise that decides whether `auto` chooses a structure on smoothed positions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from activebonds import load_model
from activebonds.data.smoothing import noise_of, smooth_positions
from activebonds.identify.costs.windows import make_windows
from activebonds.identify.settings import FitSettings
from activebonds.identify.solvers.lsq import least_squares
from activebonds.simulation import simulate

TRIANGLE = (
    Path(__file__).resolve().parents[1] / "src" / "activebonds" / "examples" / "triangle.toml"
)


def test_a_cubic_motion_passes_unchanged_and_gaps_stay_gaps():
    t = np.arange(40, dtype=np.float64)[:, None, None] / 40.0
    x = np.concatenate([1 + 2 * t - 3 * t**2 + 0.5 * t**3, -(t**3), 0 * t + 0.2], axis=2)
    x = np.repeat(x, 2, axis=1)
    mask = np.ones((40, 2), bool)
    mask[10:12, 1] = False  # a gap: runs of 10 and 28 frames
    mask[30:, 0] = False
    x[~mask] = np.nan
    out = smooth_positions(x, mask, 9)
    np.testing.assert_allclose(out[mask], x[mask], rtol=0, atol=1e-12)
    assert np.isnan(out[~mask]).all()
    noisy = x + np.random.default_rng(0).normal(0, 1e-3, x.shape)
    smoothed = smooth_positions(noisy, mask, 9)
    assert np.nanstd(smoothed - x) < 0.6 * np.nanstd(noisy - x)
    short = np.ones((40, 2), bool)
    short[4::5] = False  # runs of 4 frames: shorter than the window, left as recorded
    np.testing.assert_array_equal(
        smooth_positions(np.where(short[..., None], noisy, np.nan), short, 5)[short], noisy[short]
    )


@pytest.mark.parametrize("bad", [4, 6, 3, -1])
def test_a_bad_window_is_refused(bad):
    with pytest.raises(ValueError):
        FitSettings(smooth=bad)


def test_smoothing_the_restart_states_removes_most_of_the_noise_bias():
    """The triangle at 100 Hz with 0.5 mm marker noise, exact least squares. With raw
    backward differences the stiffnesses come out 40-75 % off (errors in variables) and the
    dampings at their bounds (+900-1900 %). With the restart states smoothed over 9 frames the
    stiffnesses are within 10 % (2-6 % here) and the dampings 3x closer, still +150-250 %:
    smoothing is a first answer, not an unbiased cost. Median over 3 noise draws."""
    model = load_model(TRIANGLE)
    clean = simulate(model, 400, 100.0)
    truth = model.layout.natural(model.layout.initial())
    names = [g.name for g in model.layout.genes]
    stiff = [i for i, n in enumerate(names) if n.endswith("stiffness")]
    damp = [i for i, n in enumerate(names) if n.endswith("damping")]
    rng = np.random.default_rng(0)
    errors = {0: [], 9: []}
    for _ in range(3):
        x = clean.positions + rng.normal(0.0, 0.5e-3, clean.positions.shape)
        for window in errors:
            w = make_windows(x, clean.mask, clean.dt, 1, window)
            found = model.layout.natural(least_squares(model, w).genome)
            errors[window].append(np.abs(found / truth - 1.0))
    raw, smooth = (np.median(errors[k], axis=0) for k in (0, 9))
    assert raw[stiff].min() > 0.3  # the bias is real
    assert smooth[stiff].max() < 0.1
    assert np.all(smooth[damp] < raw[damp] / 3)
    # the targets are the recorded positions, not smoothed
    w0, w9 = (
        make_windows(x, clean.mask, clean.dt, 1, 0),
        make_windows(x, clean.mask, clean.dt, 1, 9),
    )
    np.testing.assert_array_equal(w0.target, w9.target)
    assert not np.allclose(w0.v0, w9.v0)


def _orbit(frames: int = 400, rate: float = 100.0) -> np.ndarray:
    """Three markers on slow 3D orbits (1-2 Hz, centimetres): [F, 3, 3] metres."""
    t = np.arange(frames)[:, None] / rate
    x = np.zeros((frames, 3, 3))
    for p, f in enumerate((1.0, 1.6, 2.1)):
        x[:, p] = 0.03 * np.hstack(
            [np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t), np.sin(np.pi * f * t)]
        ) + [p * 0.3, 0.0, 0.0]
    return x


def test_the_noise_is_measured_and_a_window_chosen_only_where_it_dominates():
    from activebonds.data.smoothing import NOISE_SHARE, WINDOWS, _second_difference_gain

    clean = _orbit()
    quiet = noise_of(clean)
    assert quiet.sigma < 1e-3 and quiet.window == 0 and not quiet.dominated
    # zero force's one-step RMS of the clean motion is its second difference's
    acc = clean[2:] - 2 * clean[1:-1] + clean[:-2]
    assert quiet.zero_force == pytest.approx(np.sqrt(np.mean(np.sum(acc**2, -1))) * 1e3)
    rng = np.random.default_rng(0)
    for sigma_mm in (0.05, 0.5, 2.0):
        noisy = noise_of(clean + rng.normal(0.0, sigma_mm / 1000, clean.shape))
        assert noisy.sigma == pytest.approx(sigma_mm, rel=0.08)
        assert noisy.floor == pytest.approx(np.sqrt(18) * noisy.sigma, rel=1e-12)
        if sigma_mm < 0.1:  # the motion is what the noise leaves of zero force's error:
            assert noisy.motion == pytest.approx(quiet.zero_force, rel=0.05)  # told apart
        if noisy.floor <= NOISE_SHARE * noisy.motion:
            assert noisy.window == 0
        else:  # the smallest window that brings the floor under the share, or the largest
            fits = [w for w in WINDOWS if noisy.floor * _second_difference_gain(w)
                    <= NOISE_SHARE * noisy.motion]  # fmt: skip
            assert noisy.window == (fits[0] if fits else WINDOWS[-1])
    assert noise_of(clean + rng.normal(0.0, 5e-6, clean.shape)).window == 0
    assert noise_of(clean + rng.normal(0.0, 5e-4, clean.shape)).window > 0


def test_a_window_gain_is_the_filtered_second_difference_of_white_noise():
    from activebonds.data.smoothing import _second_difference_gain

    rng = np.random.default_rng(1)
    e = rng.normal(size=(200_000, 1, 1))
    raw = np.std(e[2:] - 2 * e[1:-1] + e[:-2])
    mask = np.ones((e.shape[0], 1), bool)
    for window in (5, 21):
        s = smooth_positions(e, mask, window)
        ratio = np.std(s[2:] - 2 * s[1:-1] + s[:-2]) / raw
        assert ratio == pytest.approx(_second_difference_gain(window), rel=0.02)
