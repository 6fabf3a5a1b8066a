"""The gait family found from a recording (identify/discover/gait/): its rhythm, its signals
and its model, checked on constructed recordings with known answers and by recovering a gait
model's parameters from its own simulation (no bundled recording, name or rate is read)."""

from __future__ import annotations

import numpy as np
import pytest

from activebonds.data import Trajectory
from activebonds.identify.discover.gait import GaitVariant, find_rhythm, gait_spec, solve, survey
from activebonds.identify.discover.gait.signals import (
    Signal,
    balanced_gain,
    fundamental,
    gain_for,
    partner,
)
from helpers import assert_periodic_coefficients


def _periodic(rate=137.0, period_s=0.83, seconds=9.0, velocity=(0.0, 0.0, 0.0), seed=3):
    """Three markers circling at one period, a quarter period apart, plus noise; the body
    carried at ``velocity``."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    w = 2 * np.pi * t / period_s
    x = np.zeros((t.size, 3, 3))
    for i, lag in enumerate((0.0, np.pi / 2, np.pi)):
        x[:, i] = np.stack([0.1 * np.cos(w - lag) + 0.5 * i, 0.05 * np.sin(w), 1.0 + 0.03 *
                            np.cos(w - lag)], axis=1)  # fmt: skip
    x += np.asarray(velocity) * t[:, None, None] + 1e-4 * rng.standard_normal(x.shape)
    return x, rate, period_s


def test_the_rhythm_is_the_period_at_any_rate_with_a_confidence():
    x, rate, period_s = _periodic()
    rhythm = find_rhythm(x, rate)
    assert rhythm.period == pytest.approx(period_s * rate, rel=0.01)
    assert rhythm.frequency == pytest.approx(1 / period_s, rel=0.01)
    assert rhythm.confidence > 0.95 and rhythm.rhythmic
    assert not rhythm.travels
    assert "confidence" in rhythm.line()


def test_a_walk_that_travels_carries_its_anchors_at_its_velocity():
    x, rate, _ = _periodic(velocity=(1.3, 0.0, 0.0))
    rhythm = find_rhythm(x, rate)
    assert rhythm.travels
    assert rhythm.velocity[0] == pytest.approx(1.3, rel=0.01)
    assert abs(rhythm.velocity[1]) < 0.01


def test_noise_has_no_rhythm_and_too_few_strides_are_not_enough():
    rng = np.random.default_rng(0)
    walk = np.cumsum(rng.standard_normal((600, 3, 3)), axis=0) * 1e-3
    found = find_rhythm(walk, 100.0)
    assert found is None or not found.rhythmic
    x, rate, _ = _periodic(seconds=2.2)  # 2.7 periods
    short = find_rhythm(x, rate)
    assert short is not None and short.strides < 3 and not short.rhythmic


def test_a_signals_fundamental_and_its_quarter_stride_partner():
    rate, f = 91.0, 1.3  # 70 frames a period, 6 periods: the mean removed is the offset
    t = np.arange(420) / rate
    s = 0.2 + 0.03 * np.cos(2 * np.pi * f * t - 0.7)
    share, amplitude, theta = fundamental(s, f, rate)
    assert share == pytest.approx(1.0, abs=1e-9)
    assert amplitude == pytest.approx(0.03, rel=1e-9)
    assert theta == pytest.approx(0.7, abs=1e-9)
    x, rate, period_s = _periodic()
    signals = survey(x, 1 / period_s, rate, (0, 1, 2))
    assert signals == sorted(signals, key=lambda s: -s.share)
    first = signals[0]
    second = partner(signals, first)
    apart = abs((second.phase - first.phase + np.pi) % (2 * np.pi) - np.pi)
    assert abs(apart - np.pi / 2) <= np.radians(30)


def test_the_gains_give_the_coupling_strength_and_balance_the_pair():
    first = Signal((0,), 2, 0.0, 0.04, 0.3, 1.0)
    second = Signal((1,), 2, 0.0, 0.02, 0.3 + np.pi / 2, 1.0)
    f = 1.2
    sigma = gain_for(first, 0.16, f)
    assert sigma * first.amplitude / 2 / (2 * np.pi * f) == pytest.approx(0.16)
    # a quarter stride apart: sigma_b A_b = sigma A
    assert balanced_gain(first, sigma, second) * second.amplitude == pytest.approx(
        sigma * first.amplitude
    )


@pytest.mark.parametrize("velocity", [(0.0, 0.0, 0.0), (0.9, 0.1, 0.0)])
def test_a_gait_model_is_recovered_from_its_own_simulation(velocity):
    """Truth: a gait model (anchors, 3 harmonics, entrained by a quarter-stride pair) with
    random coefficients, simulated at 123 Hz for 1,200 frames (semi-implicit Euler, one
    substep: the one-step cost's own integration). Its rhythm is found near the drive's
    frequency (the loop locks within the coupling's strength, 0.2, of it), and the same
    model solved on the simulation recovers every stiffness, damping and coefficient."""
    from activebonds.model import build
    from activebonds.simulation import simulate

    x, rate, period_s = _periodic(rate=123.0, velocity=velocity)
    names = ("a", "b", "c")
    rhythm = find_rhythm(x[:400], rate)
    signals = survey(x[:400], rhythm.frequency, rate, (0, 1, 2))
    spec = gait_spec(x[:400], names, rhythm, signals, GaitVariant(harmonics=3, kappa=0.2))
    rng = np.random.default_rng(7)
    bonds = []
    for b in spec.bond:
        update = {}
        if b.kind == "unary":
            lo = b.damping.min
            update = {
                "stiffness": b.stiffness.model_copy(update={"value": float(rng.uniform(20, 60))}),
                "damping": b.damping.model_copy(update={"value": lo + float(rng.uniform(1, 3))}),
            }
        else:
            for h in range(1, 4):
                for wave in ("cos", "sin"):
                    p = getattr(b, f"{wave}{h}")
                    value = [float(v) for v in rng.uniform(-2, 2, 3) / h]
                    update[f"{wave}{h}"] = p.model_copy(update={"value": value})
        bonds.append(b.model_copy(update=update))
    truth = spec.model_copy(update={"bond": bonds})
    recording = simulate(build(truth), 1200, rate)
    positions = np.asarray(recording.positions)
    assert np.isfinite(positions).all()
    found = find_rhythm(positions, rate)
    assert found is not None and found.rhythmic
    assert found.frequency == pytest.approx(spec.drive.frequency, rel=0.2)
    data = Trajectory(positions, np.ones(positions.shape[:2], bool), names, rate)
    solved = solve(spec, data, (0, 1200))
    for got, want in zip(solved.spec.bond, truth.bond, strict=True):
        if want.kind == "unary":
            assert got.stiffness.value == pytest.approx(want.stiffness.value, rel=1e-5)
            assert got.damping.value == pytest.approx(want.damping.value, rel=1e-5)
        else:
            assert_periodic_coefficients(got, want)


def test_a_window_after_the_origin_tracks_the_phase_along_the_recorded_frames_before_it():
    """``evaluate --origin``'s window: an entrained drive's phase tracked along the recorded
    frames between the origin and the window (``before``) is the phase tracked along the
    whole recording, so its predictions are the whole recording's, frame for frame; without
    them (the frames unknown) the window's first period is repeated backwards, which a window
    shorter than a period cannot do well."""
    from activebonds.identify.judge.predictions import one_step, tracked_phases

    x, rate, period_s = _periodic(rate=100.0, period_s=0.9, seconds=6.0)
    names = ("a", "b", "c")
    rhythm = find_rhythm(x[:300], rate)
    signals = survey(x[:300], rhythm.frequency, rate, (0, 1, 2))
    spec = gait_spec(x[:300], names, rhythm, signals, GaitVariant(harmonics=2, kappa=0.3))
    data = Trajectory(x, np.ones(x.shape[:2], bool), names, rate)
    model = solve(spec, data, (0, 300))
    dt, a, b = 1 / rate, 340, 400  # a window of 60 frames, shorter than the 90-frame period
    whole = tracked_phases(model, x[:b], dt)
    np.testing.assert_allclose(tracked_phases(model, x[a:b], dt, 1, a, x[:a]), whole[a:])
    np.testing.assert_allclose(
        one_step(model, x[a:b], dt, offset=a, before=x[:a])[2:], one_step(model, x[:b], dt)[a + 2 :]
    )
    unknown = tracked_phases(model, x[a:b], dt, 1, a)
    assert np.max(np.abs(unknown - whole[a:])) > 1e-3  # what the recorded frames change


def test_a_variant_judged_on_frames_too_short_for_its_gait_keeps_its_other_scores():
    """auto's gait variants are judged with the gait metrics and a burn-in where the judged
    frames allow them; a window too short for either is judged one step and ahead alone
    (no gait target counted), not refused."""
    from activebonds.auto.gait import judge

    x, rate, period_s = _periodic(rate=100.0, period_s=0.9, seconds=6.0)
    names = ("a", "b", "c")
    rhythm = find_rhythm(x[:300], rate)
    signals = survey(x[:300], rhythm.frequency, rate, (0, 1, 2))
    data = Trajectory(x, np.ones(x.shape[:2], bool), names, rate)
    model = solve(gait_spec(x[:300], names, rhythm, signals, GaitVariant(harmonics=2)), data,
                  (0, 300))  # fmt: skip
    short = judge(model, data, (300, 330), 0, 10, GaitVariant())
    assert short.targets == 0 and short.worse_markers == 0
    assert short.one_step_mm < short.zero_force_one_step_mm
    assert short.ahead_mm < short.zero_force_ahead_mm
    full = judge(model, data, (300, 600), 0, 10, GaitVariant())
    assert full.targets == 5  # the four gait targets and the burn-in's
