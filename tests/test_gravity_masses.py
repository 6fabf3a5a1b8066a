"""Unary anchors that move, gravity as a parameter and masses as ratios (issue 11, items 2-4).

* a unary bond's anchor a(t) = a + u t, F = -k (x - a(t)) - c (v - u): against the NumPy
  oracle at several times, and against the closed-form damped oscillator in the anchor's frame;
* recovery by ``fit`` (one-step cost, simulated data without noise) of a free anchor
  velocity, of a free gravity magnitude and of mass ratios with ``total_mass``;
* the scale invariance that makes masses identifiable only up to a factor, and the loader's
  refusals (every mass free without a reference, total_mass <= 0 or <= the fixed masses, a
  zero gravity direction).
"""

from __future__ import annotations

import math

import jax
import numpy as np
import pytest

import reference_numpy as ref
from activebonds import fit
from activebonds.errors import InputError
from activebonds.identify.costs.windows import make_windows
from activebonds.identify.solvers.lsq import least_squares
from activebonds.model import dumps_model, loads_model
from activebonds.physics import total_force
from activebonds.simulation import simulate
from helpers import both_ways_fresh_in_slow

# --------------------------------------------------------------------------------------------
# Moving anchors
# --------------------------------------------------------------------------------------------

TREADMILL = """
name = "treadmill"
dimension = 3
gravity = [0.0, 0.0, -9.81]

[[particle]]
name = "a"
mass = 1.2
position = [0.1, 0.0, 0.9]
velocity = [0.0, 0.2, 0.0]

[[particle]]
name = "b"
mass = 0.7
position = [0.5, 0.1, 1.0]
velocity = [0.3, 0.0, 0.0]

[[bond]]
kind = "unary"
particles = ["a"]
stiffness = 60.0
damping = 1.5
anchor = [0.0, 0.0, 1.0]
anchor_velocity = VELOCITY

[[bond]]
kind = "unary"
particles = ["b"]
stiffness = 40.0
damping = 0.8
anchor = [0.5, 0.0, 1.1]

[[bond]]
kind = "binary"
particles = ["a", "b"]
stiffness = 20.0
rest_length = 0.4
damping = 0.3
"""

U = [-0.8, 0.1, 0.05]  # m/s: a treadmill belt, mostly along -x


def treadmill(velocity: str = str(U)) -> str:
    return TREADMILL.replace("VELOCITY", velocity)


def test_moving_anchor_forces_match_the_oracle_at_several_times():
    model = loads_model(treadmill())
    params, topo = model.params, model.topology
    rng = np.random.default_rng(3)
    x = rng.normal(0.5, 0.3, (2, 3))
    v = rng.normal(0.0, 1.0, (2, 3))
    at = jax.jit(lambda t: total_force(params, topo, x, v, t))
    for t in (0.0, 0.37, 2.5, 11.0):
        expected = ref.total_force(params, topo, x, v, time=t)
        np.testing.assert_allclose(np.asarray(at(t)), expected, rtol=1e-13, atol=1e-12)
    # the anchor really moves: at t = 2.5 s the first bond's spring is 2 m longer along x
    moved = np.asarray(at(2.5)) - np.asarray(at(0.0))
    np.testing.assert_allclose(moved[0], 60.0 * np.array(U) * 2.5, rtol=1e-12)
    np.testing.assert_allclose(moved[1], 0.0, atol=1e-12)


OSCILLATOR = """
name = "follower"
dimension = 2

[[particle]]
name = "p"
mass = {m}
position = {x0}
velocity = {v0}

[[bond]]
kind = "unary"
particles = ["p"]
stiffness = {k}
damping = {c}
anchor = {a}
anchor_velocity = {u}
"""


def test_a_particle_follows_a_moving_anchor_as_a_damped_oscillator_in_its_frame():
    """In the anchor's frame y = x - a - u t the law gives m y'' = -k y - c y' exactly: the
    particle trails nothing in the steady state (with F = -k (x - a(t)) - c v it would trail
    by c u / k = 0.1 m here), and the transient is the closed-form underdamped oscillator."""
    m, k, c = 2.0, 50.0, 5.0
    a, u = np.array([0.2, -0.1]), np.array([1.0, 0.5])
    y0, w0 = np.array([0.05, -0.03]), np.array([-0.2, 0.4])

    def vec(z):
        return str([float(e) for e in z])

    text = OSCILLATOR.format(m=m, k=k, c=c, a=vec(a), u=vec(u), x0=vec(a + y0), v0=vec(u + w0))
    model = loads_model(text)
    rate, frames = 200.0, 2401  # 12 s: the transient decays as exp(-1.25 t)
    t = np.arange(frames) / rate
    zeta_w = c / (2 * m)
    wd = math.sqrt(k / m - zeta_w**2)
    decay = np.exp(-zeta_w * t)[:, None]
    y = decay * (y0 * np.cos(wd * t)[:, None] + ((w0 + zeta_w * y0) / wd) * np.sin(wd * t)[:, None])
    exact = a + u * t[:, None] + y
    errors = []
    for substeps in (20, 40):
        xs = simulate(model, frames, rate, substeps=substeps, integrator="verlet").positions[:, 0]
        errors.append(np.abs(xs - exact).max())
    # the integrator converges to the closed form (first order with a velocity-dependent force)
    assert errors[0] < 2e-5 and 1.8 < errors[0] / errors[1] < 2.2, errors
    # steady state: on the anchor to < 1 micrometre, not c u / k behind it
    assert np.abs(xs[-1] - (a + u * t[-1])).max() < 1e-6
    assert np.linalg.norm(c * u / k) > 0.1


def test_fit_recovers_a_free_anchor_velocity():
    truth = loads_model(treadmill())
    data = simulate(truth, 60, 50.0)
    start = loads_model(treadmill("{ value = [0.0, 0.0, 0.0], min = -2.0, max = 2.0 }"))
    assert [g.name for g in start.layout.genes] == [
        f"bond[0].anchor_velocity[{ax}]" for ax in range(3)
    ]
    result = fit(start, data, population=30, generations=150, seed=2, refine="none")
    found = result.model.params.bonds["unary"]["anchor_velocity"][0]
    np.testing.assert_allclose(found, U, atol=2e-3)
    assert result.rms_mm < 0.01
    # the fitted model writes back and loads to the same anchor velocity
    again = loads_model(dumps_model(result.model))
    np.testing.assert_allclose(again.params.bonds["unary"]["anchor_velocity"][0], found)


def test_least_squares_uses_a_fixed_anchor_velocity_and_refuses_a_free_one():
    truth = loads_model(treadmill())
    data = simulate(truth, 40, 50.0)
    windows = make_windows(data.positions, data.mask, data.dt, 1)
    free_kc = loads_model(
        treadmill()
        .replace("stiffness = 60.0", "stiffness = { value = 10.0, min = 0.0, max = 200.0 }")
        .replace("damping = 1.5", "damping = { value = 0.1, min = 0.0, max = 10.0 }")
    )
    found = least_squares(free_kc, windows)
    assert found.exact and found.rms_mm < 1e-9
    assert sorted(found.values.values()) == pytest.approx([1.5, 60.0], rel=1e-8)
    free_u = loads_model(treadmill("{ value = [0.0, 0.0, 0.0] }"))
    with pytest.raises(InputError, match="anchor_velocity") as err:
        least_squares(free_u, windows)
    assert "\n" not in str(err.value)


# --------------------------------------------------------------------------------------------
# Gravity as a parameter
# --------------------------------------------------------------------------------------------

PENDULUM = """
name = "pendulum"
dimension = 3
GRAVITY

[[particle]]
name = "top"
mass = 1.0
position = [0.0, 0.0, 1.0]
velocity = [0.4, 0.0, 0.3]

[[particle]]
name = "bottom"
mass = 1.5
position = [0.3, 0.1, 0.6]
velocity = [0.0, -0.5, 0.0]

[[bond]]
kind = "unary"
particles = ["top"]
stiffness = 80.0
damping = 0.5
anchor = [0.0, 0.0, 1.1]

[[bond]]
kind = "binary"
particles = ["top", "bottom"]
stiffness = 30.0
rest_length = 0.5
damping = 0.2
"""


def test_a_gravity_magnitude_is_one_gene_along_its_direction():
    free = "gravity = { value = 12.0, min = 5.0, max = 15.0, direction = [0.0, 0.0, -2.0] }"
    model = loads_model(PENDULUM.replace("GRAVITY", free))
    (gene,) = model.layout.genes
    assert gene.name == "gravity.magnitude"
    assert (gene.lower, gene.upper, gene.value) == (5.0, 15.0, 12.0)
    group = model.layout.groups.index("gravity")
    assert sorted(s for s in model.layout.group_slots[group] if s >= 0) == [0, 1]
    np.testing.assert_array_equal(model.params.gravity, [0.0, 0.0, -12.0])
    decoded = model.layout.decode(np.array([9.0]))
    np.testing.assert_allclose(np.asarray(decoded.gravity), [0.0, 0.0, -9.0])
    back = loads_model(dumps_model(model.with_genome(np.array([9.0]))))
    assert back.spec.gravity.value == 9.0
    assert back.spec.gravity.direction == [0.0, 0.0, -2.0]


def test_fit_recovers_a_free_gravity_magnitude_within_one_percent():
    truth = loads_model(PENDULUM.replace("GRAVITY", "gravity = [0.0, 0.0, -9.81]"))
    data = simulate(truth, 60, 50.0)
    free = "gravity = { value = 13.0, min = 5.0, max = 15.0, direction = [0.0, 0.0, -1.0] }"
    start = loads_model(
        PENDULUM.replace("GRAVITY", free).replace(
            "stiffness = 30.0", "stiffness = { value = 10.0, min = 1.0, max = 100.0 }"
        )
    )
    result = fit(start, data, population=30, generations=150, seed=4, refine="none")
    g = float(result.model.spec.gravity.value)
    assert abs(g - 9.81) / 9.81 < 0.01, g
    assert result.model.params.bonds["binary"]["stiffness"][0] == pytest.approx(30.0, rel=0.01)
    # and exactly by least squares, where the magnitude enters linearly (m_p n per unit)
    windows = make_windows(data.positions, data.mask, data.dt, 1)
    lsq = least_squares(start, windows)
    assert lsq.exact and lsq.rms_mm < 1e-9
    assert lsq.values[0] == pytest.approx(9.81, rel=1e-9)


# --------------------------------------------------------------------------------------------
# Masses as ratios
# --------------------------------------------------------------------------------------------

CHAIN = """
name = "chain"
dimension = 3
gravity = [0.0, 0.0, -9.81]
TOTAL

[[particle]]
name = "p0"
mass = M0
position = [0.0, 0.0, 1.0]
velocity = [0.3, 0.0, 0.0]

[[particle]]
name = "p1"
mass = M1
position = [0.4, 0.0, 0.8]
velocity = [0.0, 0.4, 0.0]

[[particle]]
name = "p2"
mass = M2
position = [0.7, 0.2, 0.6]
velocity = [0.0, 0.0, -0.3]

[[bond]]
kind = "unary"
particles = ["p0"]
stiffness = K0
damping = 0.6
anchor = [0.0, 0.0, 1.1]

[[bond]]
kind = "binary"
particles = ["p0", "p1"]
stiffness = K1
rest_length = 0.4
damping = 0.2

[[bond]]
kind = "binary"
particles = ["p1", "p2"]
stiffness = K2
rest_length = 0.35
damping = 0.2
"""
MASSES = (1.0, 2.0, 1.5)
STIFFNESS = (90.0, 40.0, 25.0)


def chain(total="", masses=MASSES, stiffness=STIFFNESS) -> str:
    text = CHAIN.replace("TOTAL", total)
    for i, m in enumerate(masses):
        text = text.replace(f"M{i}", str(m))
    for i, k in enumerate(stiffness):
        text = text.replace(f"K{i}", str(k))
    return text


FREE_MASS = "{ value = 1.0, min = 0.2, max = 5.0 }"


def test_total_mass_makes_the_free_masses_ratios_that_sum_exactly():
    model = loads_model(chain("total_mass = 500.0", masses=(FREE_MASS, 3.0, FREE_MASS)))
    names = [g.name for g in model.layout.genes]
    assert names == ["mass:p0.weight", "mass:p2.weight"]
    assert all(g.log for g in model.layout.genes)
    np.testing.assert_allclose(model.params.mass, [248.5, 3.0, 248.5])
    genome = np.log([0.3, 4.1])
    decoded = np.asarray(model.layout.decode(genome).mass)
    assert decoded.sum() == pytest.approx(500.0, rel=1e-15)
    np.testing.assert_allclose(decoded[[0, 2]] / decoded[[0, 2]].sum(), [0.3 / 4.4, 4.1 / 4.4])
    back = loads_model(dumps_model(model.with_genome(genome)))
    masses = [p.mass.value if hasattr(p.mass, "value") else p.mass for p in back.spec.particle]
    assert abs(sum(masses) - 500.0) <= 1e-12 * 500.0
    np.testing.assert_allclose(back.params.mass, decoded, rtol=1e-13)
    assert back.spec.mass_scale() == "total_mass = 500 kg"
    assert model.without(set()).spec.mass_scale() == "total_mass = 500 kg"
    fixed_one = loads_model(chain(masses=(FREE_MASS, 3.0, FREE_MASS)))
    assert fixed_one.spec.mass_scale() == "particle p1's mass (fixed)"
    assert loads_model(chain()).spec.mass_scale() == "not identified: no free masses"


def test_fit_recovers_mass_ratios_with_a_total_mass_within_two_percent():
    truth = loads_model(chain())
    data = simulate(truth, 60, 50.0)
    free_k = "{ value = 50.0, min = 5.0, max = 500.0 }"
    start = loads_model(
        chain(f"total_mass = {sum(MASSES)}", masses=(FREE_MASS,) * 3, stiffness=(free_k,) * 3)
    )
    result = fit(start, data, population=60, generations=1500, seed=5, refine="none")
    found = np.asarray(result.model.params.mass)
    np.testing.assert_allclose(found, MASSES, rtol=0.02)
    np.testing.assert_allclose(
        result.model.params.bonds["binary"]["stiffness"], [40, 25], rtol=0.02
    )
    written = loads_model(dumps_model(result.model))
    total = sum(p.mass.value for p in written.spec.particle)
    assert abs(total - sum(MASSES)) <= 1e-12 * sum(MASSES)


def test_scaling_every_mass_and_coefficient_leaves_the_trajectory_unchanged():
    """m, k, c and muscle gains times 3 (gravity included, as it acts as m g): the same
    simulated trajectory, which is why the loader wants a reference mass."""
    neural = """
[[bond]]
kind = "binary"
particles = ["p0", "p2"]
stiffness = SK
rest_length = 0.8
damping = SC
neural = true
gain = SG
threshold = 0.1
weights = { length = [0.5, -0.3, 0.0], rate = [0.2, 0.1, 0.0] }

[[bond]]
kind = "ternary"
particles = ["p0", "p1", "p2"]
stiffness = ST
rest_angle = 2.5
"""

    def scaled(f):
        text = chain(masses=[f * m for m in MASSES], stiffness=[f * k for k in STIFFNESS])
        text = text.replace("damping = 0.6", f"damping = {0.6 * f}")
        text = text.replace("damping = 0.2", f"damping = {0.2 * f}")
        text = text.replace('anchor = [0.0, 0.0, 1.1]', 'anchor = [0.0, 0.0, 1.1]\n'
                            'anchor_velocity = [0.2, 0.0, 0.0]')  # fmt: skip
        extra = neural.replace("SK", str(5.0 * f)).replace("SC", str(0.1 * f))
        extra = extra.replace("SG", str(4.0 * f)).replace("ST", str(2.0 * f))
        return loads_model(text + extra)

    one, three = scaled(1.0), scaled(3.0)
    a = simulate(one, 150, 100.0).positions
    b = simulate(three, 150, 100.0).positions
    assert np.ptp(a, axis=0).max() > 0.1  # it moved
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------------------------
# Bad input: one line naming the file, exit 2
# --------------------------------------------------------------------------------------------

BAD = [
    (chain(masses=(FREE_MASS,) * 3), "every mass is free"),
    (chain("total_mass = 0.0", masses=(FREE_MASS,) * 3), "total_mass: must be > 0"),
    (chain("total_mass = -5.0", masses=(FREE_MASS, 1.0, 1.0)), "total_mass: must be > 0"),
    (chain("total_mass = 3.0", masses=(FREE_MASS, 2.0, 1.5)), "must exceed the fixed masses"),
    (
        PENDULUM.replace("GRAVITY", "gravity = { value = 9.81, direction = [0.0, 0.0, 0.0] }"),
        "gravity.direction: must be a non-zero vector",
    ),
]


@pytest.mark.parametrize("text,message", BAD)
def test_bad_mass_and_gravity_input_is_one_line(text, message):
    with pytest.raises(InputError, match=message):
        loads_model(text, "bad.toml")


@pytest.mark.parametrize(*both_ways_fresh_in_slow())
def test_bad_model_through_the_cli_is_one_line_and_exit_2(tmp_path, run):
    for n, (text, message) in enumerate(BAD[:1] + BAD[-1:]):
        path = tmp_path / f"bad{n}.toml"
        path.write_text(text)
        proc = run("simulate", path, "--n-frames", "3", "--rate", "10", "--out", tmp_path / "o.csv")
        assert proc.returncode == 2, proc.stderr
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and str(path.name) in lines[0] and message in lines[0], lines
