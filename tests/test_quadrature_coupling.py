"""The entrained drive's second signal (DESIGN.md §2, "Entrained drive"): d psi/dt = 2 pi f -
sigma s cos psi - sigma_b s_b sin psi, s_b the ``[drive.coupling] quadrature`` signal.

Checked here: the model file (the gene, either sign, write-back, one-line load errors), the
integrator against the NumPy oracle, a balanced pair a quarter period apart pulling the phase
without the one signal's ripple, the tracked phase, the restart and shooting costs vanishing
at the truth, and frequency, both gains and the drive weights recovered from a simulation.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import reference_numpy as ref
from activebonds import fit
from activebonds.errors import InputError
from activebonds.identify.costs.shooting import make_shooting, shooting_windows
from activebonds.identify.costs.shooting import start_states as window_starts
from activebonds.identify.costs.windows import make_cost, make_windows
from activebonds.identify.gaps.dynamics import fill_phases
from activebonds.identify.judge.predictions import tracked_phases
from activebonds.model import dumps_model, loads_model
from activebonds.physics import phase, rollout, rollout_states
from activebonds.simulation import simulate
from test_entrained_drive import START, entrained

QUADRATURE = (
    'quadrature = {{ signal = "length", particles = ["A", "C"], gain = {gain}, offset = 0.45 }}'
)
TRUTH = {"frequency": 1.5, "gain": 20.0, "quadrature": 15.0}


def with_quadrature(text: str, gain="15.0") -> str:
    """The entrained triangle with a second signal: the distance A-C about 0.45 m."""
    old = "start_phase = "
    head, _, tail = text.partition(old)
    start, _, rest = tail.partition(" }")
    return f"{head}{old}{start}, {QUADRATURE.format(gain=gain)} }}{rest}"


def model_text(frequency="1.5", gain="20.0", start="0.5", quadrature="15.0", **replace) -> str:
    return with_quadrature(entrained(frequency, gain, start, **replace), quadrature)


# --------------------------------------------------------------------------------------------
# The model file
# --------------------------------------------------------------------------------------------


def test_the_second_gain_is_a_gene_of_either_sign_and_writes_back():
    model = loads_model(model_text(quadrature="{ value = -12.0, min = -40.0, max = 40.0 }"))
    gene = model.layout.genes[0]
    assert (gene.name, gene.lower, gene.upper, gene.log) == (
        "drive.coupling.quadrature.gain",
        -40.0,
        40.0,
        False,
    )
    np.testing.assert_array_equal(
        model.params.bonds["binary"]["drive_quadrature_gain"], [-12.0, -12.0, 0.0]
    )
    c = model.topology.drive
    assert c.quadrature == ((0, 2), 2, 0.45) and c.read == (2, 0)
    genome = model.layout.initial() + 5.0 * np.eye(model.layout.n_genes)[0]
    text = dumps_model(model.with_genome(genome))
    again = loads_model(text)
    q = again.spec.drive.coupling.quadrature
    assert q.gain.value == pytest.approx(-7.0, rel=1e-14) and (q.gain.min, q.gain.max) == (-40, 40)
    assert (q.signal, q.particles, q.offset) == ("length", ["A", "C"], 0.45)
    assert dumps_model(again) == text


def test_default_bounds_are_symmetric():
    model = loads_model(model_text(quadrature="{ value = 30.0 }"))
    gene = model.layout.genes[0]
    assert (gene.lower, gene.upper) == (-100.0, 100.0)


def test_a_model_without_it_has_no_second_gain():
    model = loads_model(entrained())
    assert model.topology.drive.quadrature is None
    assert not model.params.bonds["binary"]["drive_quadrature_gain"].any()
    assert "quadrature" not in dumps_model(model)


@pytest.mark.parametrize(
    "replace,message",
    [
        (
            {'"length", particles = ["A", "C"]': '"length", particles = ["A", "Q"]'},
            r"drive\.coupling\.quadrature\.particles: unknown particle 'Q'",
        ),
        (
            {'"length", particles = ["A", "C"]': '"length", particles = ["A"]'},
            r"drive\.coupling\.quadrature\.particles: a length signal needs particles = \[A, B\]",
        ),
        (
            {'signal = "length", particles = ["A", "C"]': 'particles = ["A", "C"]'},
            r"drive\.coupling\.quadrature\.particle: a height signal needs particle",
        ),
        (
            {'signal = "length", particles = ["A", "C"]': 'particle = "Z"'},
            r"drive\.coupling\.quadrature\.particle: unknown particle 'Z'",
        ),
        ({"gain = 15.0, ": ""}, r"drive\.coupling\.quadrature\.gain: required key is missing"),
        ({"offset = 0.45": "offset = 0.45, start_phase = 1.0"}, r"quadrature\.start_phase"),
        ({"gain = 15.0": "gain = nan"}, r"drive\.coupling\.quadrature\.gain"),
        ({"offset = 0.45": 'offset = "x"'}, r"drive\.coupling\.quadrature\.offset"),
    ],
    ids=[
        "unknown",
        "length-one-particle",
        "height-two-particles",
        "height-unknown",
        "no-gain",
        "unknown-key",
        "nan-gain",
        "bad-offset",
    ],
)
def test_load_errors_are_one_line(replace, message):
    text = model_text()
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    with pytest.raises(InputError, match=message) as err:
        loads_model(text, "quadrature.toml")
    assert "\n" not in str(err.value)


def test_not_a_table_is_one_line():
    text = model_text().replace(QUADRATURE.format(gain="15.0"), "quadrature = 3.0")
    with pytest.raises(InputError, match=r"drive\.coupling\.quadrature: expected a table") as err:
        loads_model(text, "quadrature.toml")
    assert "\n" not in str(err.value)


# --------------------------------------------------------------------------------------------
# Physics
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("height", [False, True], ids=["length", "height"])
def test_the_integrator_matches_the_numpy_oracle(height):
    text = model_text()
    if height:  # the second signal B's height about 0.05 m
        text = text.replace('signal = "length", particles = ["A", "C"]', 'particle = "B"')
        text = text.replace("offset = 0.45", "offset = 0.05")
    model = loads_model(text)
    x0, v0 = model.initial_state()
    c = model.topology.drive
    q = c.quadrature
    coupling = {
        "particles": c.particles,
        "axis": c.axis,
        "offset": c.offset,
        "frequency": 1.5,
        "gain": 20.0,
        "psi0": 0.5,
        "quadrature": {"particles": q.particles, "axis": q.axis, "offset": q.offset, "gain": 15.0},
    }
    with jax.enable_x64(True):
        xs, psis = rollout(
            model.params, model.topology, jnp.asarray(x0), jnp.asarray(v0), 1 / 60, 90, 3,
            "euler", 0.0, 0.5,
        )  # fmt: skip
    want_x, want_psi = ref.entrained_rollout(
        jax.tree_util.tree_map(np.asarray, model.params), model.topology, x0, v0, 1 / 60, 90,
        coupling, substeps=3,
    )  # fmt: skip
    np.testing.assert_allclose(np.asarray(xs), want_x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(psis), want_psi, rtol=0, atol=1e-11)
    one = dict(coupling, quadrature=None)
    _, alone = ref.entrained_rollout(
        jax.tree_util.tree_map(np.asarray, model.params), model.topology, x0, v0, 1 / 60, 90,
        one, substeps=3,
    )  # fmt: skip
    assert np.abs(want_psi - alone).max() > 0.05  # the second term moves the phase


def test_a_zero_second_gain_is_the_one_signal_drive():
    model = loads_model(model_text(quadrature="0.0"))
    one = loads_model(entrained())
    x0, v0 = (jnp.asarray(a) for a in model.initial_state())
    with jax.enable_x64(True):
        xs, psis = rollout(model.params, model.topology, x0, v0, 1 / 60, 120, 2, "euler", 0, 0.5)
        wx, wpsi = rollout(one.params, one.topology, x0, v0, 1 / 60, 120, 2, "euler", 0, 0.5)
    np.testing.assert_array_equal(np.asarray(xs), np.asarray(wx))
    np.testing.assert_array_equal(np.asarray(psis), np.asarray(wpsi))


def test_a_balanced_pair_a_quarter_period_apart_locks_without_the_ripple():
    """Signals s = A cos(Omega t), s_b = A sin(Omega t) (Omega 2 pi 1.6 Hz, the drive 1.5 Hz):
    one signal at sigma A / 2 = 2 rad/s locks with its rate rippling by about +-sigma A / 2
    twice a period; the balanced pair at the same sigma locks with a rate that does not
    ripple (d psi/dt = 2 pi f - sigma A cos(Omega t - psi): constant once locked)."""
    model = loads_model(model_text(gain="40.0", quadrature="40.0"))
    topo = model.topology
    params = jax.tree_util.tree_map(np.asarray, model.params)
    omega, a, dt = 2 * math.pi * 1.6, 0.1, 1 / 600
    t = np.arange(6000) * dt
    pair = np.stack([a * np.cos(omega * t), a * np.sin(omega * t)], axis=1)
    rates = {}
    with jax.enable_x64(True):
        for name, s in (("pair", pair), ("one", pair * [1.0, 0.0])):
            psi = np.asarray(phase.track(params, topo, jnp.asarray(s), dt, 1, 0.0))
            rate = np.diff(psi[-1200:]) / dt / omega  # over the last 2 s
            rates[name] = (rate.mean(), rate.min(), rate.max())
    assert rates["pair"][0] == pytest.approx(1.0, abs=1e-3)
    assert rates["one"][0] == pytest.approx(1.0, abs=1e-2)
    assert rates["pair"][2] - rates["pair"][1] < 1e-6
    assert rates["one"][2] - rates["one"][1] > 0.2  # measured: +-0.2 of the rate, twice a cycle


# --------------------------------------------------------------------------------------------
# Tracking and costs on the model's own simulation (one Euler substep: exact)
# --------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def simulated():
    text = model_text(
        "{ value = 1.5, min = 1.0, max = 2.0 }",
        "{ value = 20.0, min = 0.0, max = 50.0 }",
        quadrature="{ value = 15.0, min = -50.0, max = 50.0 }",
    )
    model = loads_model(text)
    return model, simulate(model, 120, 60.0)


def test_the_tracked_phase_is_the_simulated_one(simulated):
    model, data = simulated
    x0, v0 = (jnp.asarray(a) for a in model.initial_state())
    with jax.enable_x64(True):
        _, psis = rollout(model.params, model.topology, x0, v0, 1 / 60, 120, 1, "euler", 0, 0.5)
    tracked = tracked_phases(model, data.positions, data.dt)
    np.testing.assert_allclose(tracked, np.asarray(psis), rtol=0, atol=1e-10)
    filled = fill_phases(model, model.layout.initial(), data.positions, data.mask, data.dt)
    np.testing.assert_allclose(filled, tracked, rtol=0, atol=1e-10)
    gappy = data.positions.copy()
    gappy[50:52, 0] = np.nan  # A: read by the second signal only
    assert np.abs(tracked_phases(model, gappy, data.dt) - tracked).max() < 1e-3


def test_the_costs_vanish_at_the_truth(simulated):
    model, data = simulated
    windows = make_windows(data.positions, data.mask, data.dt, 5)
    shot = shooting_windows(data.positions, data.mask, data.dt, 10)
    residuals, _ = make_shooting(model, shot)
    with jax.enable_x64(True):
        genome = jnp.asarray(model.layout.initial())
        restart = jax.jit(make_cost(model, windows))  # compiled once for both genomes
        cost, _ = restart(genome)
        wrong = model.layout.initial() + np.eye(model.layout.n_genes)[2] * 2.0  # sigma_b
        worse, _ = restart(jnp.asarray(wrong))
        x0, v0 = (jnp.asarray(a) for a in model.initial_state())
        xs, vs, _ = rollout_states(
            model.params, model.topology, x0, v0, data.dt, 119, 1, "euler", 0, 0.5
        )
        x = np.concatenate([np.asarray(x0)[None], np.asarray(xs)])
        v = np.concatenate([np.asarray(v0)[None], np.asarray(vs)])
        states = tuple(jnp.asarray(a) for a in window_starts(shot, [(x, v)]))
        out = jax.jit(residuals)(genome, states)
    assert model.layout.genes[2].name == "drive.coupling.quadrature.gain"
    assert float(cost) < 1e-24 and float(worse) > 1e-8
    assert max(float(jnp.abs(r).max()) for r in out) < 1e-10


# --------------------------------------------------------------------------------------------
# Recovery from a simulation at fine substeps
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_fit_recovers_frequency_both_gains_and_weights():
    """3 s simulated at 4 substeps a frame, fitted at the same substeps (ES, then LM on the
    one-step cost): frequency, both gains, weights and phases within 1 %."""
    data = simulate(loads_model(model_text()), n_frames=180, rate=60.0, substeps=4)
    start = loads_model(
        model_text(
            "{ value = 1.4, min = 1.0, max = 2.0 }",
            "{ value = 10.0, min = 0.0, max = 50.0 }",
            quadrature="{ value = 5.0, min = -50.0, max = 50.0 }",
            **START,
        )
    )
    result = fit(start, data, population=40, generations=200, seed=0, substeps=4)
    binary = result.model.params.bonds["binary"]
    assert binary["drive_frequency"][0] == pytest.approx(TRUTH["frequency"], rel=0.01)
    assert binary["drive_gain"][0] == pytest.approx(TRUTH["gain"], rel=0.01)
    assert binary["drive_quadrature_gain"][0] == pytest.approx(TRUTH["quadrature"], rel=0.01)
    np.testing.assert_allclose(binary["drive_weight"][:2], [1.2, 0.9], rtol=0.01)
    np.testing.assert_allclose(binary["drive_phase"][:2], [0.8, -1.9], rtol=0.01)
