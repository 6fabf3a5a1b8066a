"""The periodic force (DESIGN.md §2, "Periodic force"): F_p += sum_h C_h cos(h psi) + S_h
sin(h psi), psi the model's rhythmic drive (a clock, or entrained by the body).

Checked here: the model file (genes, write-back, a drive without neurons, load errors), the
forces and an entrained free run against the NumPy oracle, the exact least squares on the
model's own simulation, the free run settling on the drive's period, and a fit recovering
frequency, coupling gain and every coefficient within 1 %.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import reference_numpy as ref
from activebonds import fit
from activebonds.errors import InputError
from activebonds.identify.costs.windows import make_cost, make_windows
from activebonds.identify.search.population_cost import make_population_cost
from activebonds.identify.solvers.lsq import least_squares
from activebonds.model import dumps_model, loads_model
from activebonds.physics import total_force
from activebonds.physics.phase import at_phase
from activebonds.simulation import simulate

# Two particles, each held by an anchor spring and damper and forced by a Fourier series in
# the drive's phase; the phase entrained by A's height, which the forcing itself moves.
PAIR = """
name = "forced_pair"
dimension = 3

[drive]
frequency = FREQUENCY
coupling = { particle = "A", gain = GAIN, offset = 0.0, start_phase = 0.3 }

[[particle]]
name = "A"
mass = 2.0
position = [0.0, 0.0, 0.0]

[[particle]]
name = "B"
mass = 1.0
position = [0.5, 0.0, 0.0]

[[bond]]
kind = "binary"
particles = ["A", "B"]
stiffness = 40.0
rest_length = 0.5
damping = 1.0

[[bond]]
kind = "unary"
particles = ["A"]
stiffness = 60.0
damping = 3.0
anchor = [0.0, 0.0, 0.0]

[[bond]]
kind = "unary"
particles = ["B"]
stiffness = 30.0
damping = 2.0
anchor = [0.5, 0.0, 0.0]

[[bond]]
kind = "periodic"
particles = ["A"]
cos1 = COS1
sin1 = SIN1
cos2 = [0.0, 0.5, -1.0]

[[bond]]
kind = "periodic"
particles = ["B"]
sin1 = SINB
"""
TRUTH = {
    "FREQUENCY": "1.5",
    "GAIN": "20.0",
    "COS1": "[2.0, 0.0, 6.0]",
    "SIN1": "[0.0, 1.0, -3.0]",
    "SINB": "[1.5, -0.5, 2.0]",
}
FREE = {
    "FREQUENCY": "{ value = 1.4, min = 1.0, max = 2.0 }",
    "GAIN": "{ value = 10.0, min = 0.0, max = 50.0 }",
    "COS1": "{ value = [0.0, 0.0, 0.0], min = -20.0, max = 20.0 }",
    "SIN1": "{ value = [0.0, 0.0, 0.0], min = -20.0, max = 20.0 }",
    "SINB": "{ value = [0.0, 0.0, 0.0], min = -20.0, max = 20.0 }",
}


def pair(**values: str) -> str:
    text = PAIR
    for key, value in {**TRUTH, **values}.items():
        text = text.replace(key, value)
    return text


def coefficients(model) -> np.ndarray:
    p = model.params.bonds["periodic"]
    return np.concatenate(
        [np.asarray(p["cos1"][0]), np.asarray(p["sin1"][0]), np.asarray(p["sin1"][1])]
    )


TRUE_COEFFICIENTS = np.array([2.0, 0.0, 6.0, 0.0, 1.0, -3.0, 1.5, -0.5, 2.0])


# --------------------------------------------------------------------------------------------
# The model file
# --------------------------------------------------------------------------------------------


def test_genes_are_named_and_the_model_writes_back():
    model = loads_model(pair(FREQUENCY=FREE["FREQUENCY"], SINB=FREE["SINB"]))
    assert [g.name for g in model.layout.genes] == [
        "drive.frequency",
        "bond[4].sin1[0]",
        "bond[4].sin1[1]",
        "bond[4].sin1[2]",
    ]
    again = loads_model(dumps_model(model))
    assert [g.name for g in again.layout.genes] == [g.name for g in model.layout.genes]
    np.testing.assert_array_equal(again.params.bonds["periodic"]["cos2"], [[0, 0.5, -1], [0, 0, 0]])
    # the drive's numbers are copies in every bond that reads it, the entrained drive held by
    # the first periodic force (no neuron in this model)
    assert model.topology.drive.kind == "periodic" and model.topology.drive.holder == 0
    np.testing.assert_array_equal(model.params.bonds["periodic"]["drive_gain"], [20.0, 20.0])


def test_a_drive_shared_with_neurons_is_one_gene():
    """A neural bond and a periodic force read the same drive: one frequency gene."""
    text = pair(FREQUENCY=FREE["FREQUENCY"]).replace(
        "damping = 1.0\n", "damping = 1.0\nneural = true\ngain = 0.5\ndrive_weight = 1.0\n", 1
    )
    model = loads_model(text)
    names = [g.name for g in model.layout.genes]
    assert names.count("drive.frequency") == 1
    assert model.topology.drive.kind == "binary"
    np.testing.assert_array_equal(model.params.bonds["periodic"]["drive_frequency"], [1.4, 1.4])


def test_a_periodic_force_needs_a_drive():
    without = pair().split("[drive]")[0] + "[[particle]]" + pair().split("[[particle]]", 1)[1]
    with pytest.raises((InputError, ValueError), match=r"needs the model's top-level \[drive\]"):
        loads_model(without)


# --------------------------------------------------------------------------------------------
# Physics against the NumPy oracle
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("psi", [None, 0.7, -2.4])
def test_the_forces_match_the_numpy_oracle(psi):
    model = loads_model(pair())
    rng = np.random.default_rng(0)
    x = rng.normal(size=(2, 3)) * 0.3
    v = rng.normal(size=(2, 3))
    t = 0.37
    params = model.params if psi is None else at_phase(model.params, psi)
    with jax.enable_x64(True):
        got = np.asarray(total_force(params, model.topology, jnp.asarray(x), jnp.asarray(v), t))
    numpy = jax.tree_util.tree_map(np.asarray, model.params)
    want = ref.total_force(numpy, model.topology, x, v, t, phase=psi)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_the_entrained_free_run_matches_the_numpy_oracle():
    model = loads_model(pair())
    data = simulate(model, 90, 60.0)
    numpy = jax.tree_util.tree_map(np.asarray, model.params)
    coupling = {"particles": (0,), "axis": 2, "offset": 0.0, "frequency": 1.5, "gain": 20.0}
    x0 = data.positions[0]
    want, _ = ref.entrained_rollout(
        numpy, model.topology, x0, np.zeros_like(x0), 1 / 60, 90, {**coupling, "psi0": 0.3}
    )
    np.testing.assert_allclose(data.positions, want, atol=1e-9)


def upward_crossings(z: np.ndarray) -> np.ndarray:
    """The (interpolated) frames where z crosses its mean upwards."""
    z = z - z.mean()
    k = np.flatnonzero((z[:-1] < 0) & (z[1:] >= 0))
    return k + z[k] / (z[k] - z[k + 1])


def test_the_free_run_settles_on_a_period():
    """Damped, anchored and forced, the free run settles on a periodic orbit: with the clock
    (gain 0) of the drive's own period, 40 frames at 1.5 Hz; entrained, of the period the
    closed loop picks (the phase is pulled by the motion it drives: measured 38.45 frames;
    the transient decays over about a second, 60 frames)."""
    clock = simulate(loads_model(pair(GAIN="0.0")), 900, 60.0).positions[:, 0, 2]
    np.testing.assert_allclose(clock[700:860], clock[740:900], atol=1e-3 * np.ptp(clock[700:]))
    entrained = simulate(loads_model(pair()), 1200, 60.0).positions[:, 0, 2]
    periods = np.diff(upward_crossings(entrained[800:]))
    assert np.ptp(periods) < 0.01 and np.ptp(entrained[800:]) > 0.05
    assert periods.mean() == pytest.approx(38.45, abs=0.05)


# --------------------------------------------------------------------------------------------
# Identification
# --------------------------------------------------------------------------------------------


def test_the_exact_least_squares_recovers_the_coefficients():
    """At the true drive numbers the one-step cost is linear in the coefficients: one Euler
    substep, the model's own simulation, the optimum is the truth."""
    data = simulate(loads_model(pair()), 180, 60.0)
    start = loads_model(pair(COS1=FREE["COS1"], SIN1=FREE["SIN1"], SINB=FREE["SINB"]))
    windows = make_windows(data.positions, data.mask, data.dt, 1)
    result = least_squares(start, windows)
    values = np.array([result.values[g] for g in range(start.layout.n_genes)])
    assert result.exact and result.rms_mm < 1e-6
    np.testing.assert_allclose(values, TRUE_COEFFICIENTS, atol=1e-7)


@pytest.mark.slow
def test_fit_recovers_frequency_gain_and_coefficients():
    """3 s simulated at 4 substeps a frame, fitted at the same substeps (ES then LM):
    frequency, coupling gain and the nine coefficients within 1 %."""
    data = simulate(loads_model(pair()), n_frames=180, rate=60.0, substeps=4)
    start = loads_model(pair(**FREE))
    result = fit(start, data, population=40, generations=200, seed=0, substeps=4)
    p = result.model.params.bonds["periodic"]
    assert float(p["drive_frequency"][0]) == pytest.approx(1.5, rel=0.01)
    assert float(p["drive_gain"][0]) == pytest.approx(20.0, rel=0.01)
    got = coefficients(result.model)
    nonzero = TRUE_COEFFICIENTS != 0
    np.testing.assert_allclose(got[nonzero], TRUE_COEFFICIENTS[nonzero], rtol=0.01)
    assert np.abs(got[~nonzero]).max() < 0.01 * np.abs(TRUE_COEFFICIENTS).max()


def test_the_population_cost_is_the_cost_with_a_clock():
    """Without coupling the drive is the clock 2 pi f t: the ES's population one-step cost
    (the periodic forces vmapped beside the batched kinds) equals the cost, at several
    individuals."""
    text = pair(FREQUENCY=FREE["FREQUENCY"], COS1=FREE["COS1"], SINB=FREE["SINB"])
    clock = loads_model("\n".join(line for line in text.splitlines() if "coupling" not in line))
    data = simulate(clock, 90, 60.0)
    windows = make_windows(data.positions, data.mask, data.dt, 1)
    rng = np.random.default_rng(1)
    lo, hi = clock.layout.lower, clock.layout.upper  # search space
    search = lo + (hi - lo) * rng.random((4, clock.layout.n_genes))
    with jax.enable_x64(True):
        population, _ = make_population_cost(clock, windows, dtype=jnp.float64)(jnp.asarray(search))
        one = jax.jit(make_cost(clock, windows))  # compiled once for the 4 individuals
        each = [float(one(jnp.asarray(s))[0]) for s in search]
    np.testing.assert_allclose(np.asarray(population), each, rtol=1e-9)


def test_mujoco_export_refuses_it_in_one_line():
    from activebonds.export.mjcf import check_exportable

    with pytest.raises(InputError, match=r"2 periodic bonds \(bond\[3\], bond\[4\]; a force"):
        check_exportable(loads_model(pair()))


# --------------------------------------------------------------------------------------------
# The bundled horse's fitted gait (scripts/horse_gait.py, docs/experiments/gait.md)
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_the_trot_gait_example_free_runs_a_gait_on_the_held_out_frames():
    """examples/horse_trot_gait.toml, fitted on frames 0-299, judged on 300-599 with its time
    from frame 0, its phase tracked along the recorded frames 0-299 (one step 2.820 mm, 10
    ahead 25.75 mm, 14.5 frames within 50 mm, body markers 97.5; period 41.42 frames against
    the recording's 41.68, hoof excursions within 8 %, cycle-average RMS 26.3 mm; the body
    111.0 mm from its mean). Before issue 44 the frames 0-299 were taken as the window's first
    stride repeated backwards: docs/results/horse_gait_950449b.json's 2.847 mm, 26.1 mm, 13.5
    and 97 frames, 26.4 mm."""
    from activebonds.data import read_trajectory
    from activebonds.data.bundled import dataset
    from activebonds.model import load_model
    from activebonds.report.evaluate import evaluate
    from helpers import ROOT

    model = load_model(ROOT / "examples" / "horse_trot_gait.toml")
    traj = read_trajectory(dataset("horse-trot").path)
    found = evaluate(
        model,
        traj,
        frames=(300, 600),
        origin=0,
        horizon=10,
        body=("Head", "Withers", "Sacrum"),
        gait=True,
        feet=("HFL", "HFR", "HHL", "HHR"),
        up=(0.0, 0.0, 1.0),
    )
    one, ahead = found.comparisons[0], found.comparisons[-1]
    assert one.model_mm == pytest.approx(2.820, abs=0.002) and one.model_mm < 3.5
    assert ahead.model_mm == pytest.approx(25.75, abs=0.1)
    assert found.model.median_frames_within == 14.5
    assert found.body["model"].median_frames_within == 97.5
    gait = found.gait.model
    assert abs(gait.period_error) < 0.03 and gait.period_frames == pytest.approx(41.42, abs=0.01)
    assert np.all(np.abs(np.asarray(gait.excursion_ratio) - 1.0) < 0.08)
    assert gait.cycle_rms_mm == pytest.approx(26.3, abs=0.1)
    assert gait.body_distance_mm == pytest.approx(111.0, abs=0.1)  # over 100: not met


def test_evaluate_refuses_an_origin_after_the_window():
    from activebonds.report.evaluate import evaluate

    model = loads_model(pair())
    data = simulate(model, 60, 60.0)
    with pytest.raises(InputError, match="--origin: must be a frame from 0 to the window's first"):
        evaluate(model, data, frames=(10, 60), origin=20, horizon=1)
