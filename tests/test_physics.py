"""Physics against an independent NumPy reference, analytic results and conservation laws."""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import reference_numpy as ref
from activebonds.model import Params, Topology, load_model, loads_model
from activebonds.physics import (
    euler_step,
    forces,
    neuron_activity,
    rollout,
    rollout_states,
    total_force,
    verlet_step,
)

# --------------------------------------------------------------------------------------------
# Random systems
# --------------------------------------------------------------------------------------------


def random_topology(rng, n_particles, dim, n_unary=3, n_binary=6, n_ternary=4, neural=None):
    if neural is None:
        neural = rng.random(n_binary) < 0.5

    def pick(n, arity):
        rows = [rng.choice(n_particles, arity, replace=False) for _ in range(n)]
        return np.array(rows, dtype=np.int32).reshape(-1, arity)

    return Topology(
        n_particles=n_particles,
        dimension=dim,
        bonds={
            "unary": {"particles": rng.integers(0, n_particles, n_unary).astype(np.int32)[:, None]},
            "binary": {
                "particles": pick(n_binary, 2),
                "neural": np.asarray(neural, dtype=bool).reshape(n_binary),
            },
            "ternary": {"particles": pick(n_ternary, 3)},
        },
    )


def random_params(rng, topo: Topology) -> Params:
    p, d = topo.n_particles, topo.dimension
    u, b, t = topo.count("unary"), topo.count("binary"), topo.count("ternary")
    params = Params(
        mass=rng.uniform(0.3, 3.0, p),
        gravity=rng.normal(0.0, 5.0, d),
        bonds={
            "unary": {
                "stiffness": rng.uniform(0.0, 100.0, u),
                "damping": rng.uniform(0.0, 3.0, u),
                "anchor": rng.normal(0.0, 1.0, (u, d)),
            },
            "binary": {
                "stiffness": rng.uniform(0.0, 100.0, b),
                "rest_length": rng.uniform(0.2, 1.5, b),
                "damping": rng.uniform(0.0, 3.0, b),
                "gain": rng.uniform(0.0, 20.0, b),
                "threshold": rng.normal(0.0, 1.0, b),
                # the diagonal is non-zero on purpose: a neuron must ignore its own bond
                "length_weights": rng.normal(0.0, 0.5, (b, b)),
                "rate_weights": rng.normal(0.0, 0.5, (b, b)),
            },
            "ternary": {
                "stiffness": rng.uniform(0.0, 10.0, t),
                "rest_angle": rng.uniform(0.0, math.pi, t),
            },
        },
    )
    # drawn last, so that the other parameters are those drawn before it existed
    params.bonds["unary"]["anchor_velocity"] = rng.normal(0.0, 0.3, (u, d))
    return params


def replace(params: Params, gravity=None, mass=None, **kinds) -> Params:
    """``params`` with some arrays replaced: ``replace(p, binary={"stiffness": ...})``."""
    bonds = {k: {**fields, **kinds.get(k, {})} for k, fields in params.bonds.items()}
    return Params(
        mass=params.mass if mass is None else mass,
        gravity=params.gravity if gravity is None else gravity,
        bonds=bonds,
    )


def neural_of(topo: Topology) -> np.ndarray:
    return topo.bonds["binary"]["neural"]


def random_state(rng, n_particles, dim, min_distance=0.2):
    while True:
        x = rng.uniform(-1.0, 1.0, (n_particles, dim))
        dist = np.linalg.norm(x[:, None] - x[None], axis=-1) + np.eye(n_particles)
        if dist.min() > min_distance:
            return x, rng.normal(0.0, 1.0, (n_particles, dim))


def random_system(seed, dim, n_particles=6, **kw):
    rng = np.random.default_rng(seed)
    topo = random_topology(rng, n_particles, dim, **kw)
    params = random_params(rng, topo)
    x, v = random_state(rng, n_particles, dim)
    return params, topo, x, v


def assert_close(actual, expected, rtol=1e-12):
    actual, expected = np.asarray(actual), np.asarray(expected)
    scale = max(float(np.abs(expected).max(initial=0.0)), 1e-300)
    np.testing.assert_allclose(actual, expected, rtol=rtol, atol=rtol * scale)


EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SYSTEMS = [(seed, dim) for dim in (2, 3) for seed in range(3)]
FAMILY_PAIRS = [
    ("uniform_field", forces.uniform_field),
    ("unary", functools.partial(forces.bond_forces, "unary")),
    ("binary", functools.partial(forces.bond_forces, "binary")),
    ("ternary", functools.partial(forces.bond_forces, "ternary")),
]


def ref_family(name, params, topo, x, v):
    if name == "uniform_field":
        return ref.uniform_field_force(params, topo, x, v)
    return ref.kind_force(name, params, topo, x, v)


def binary(params, topo, x, v):
    return forces.bond_forces("binary", params, topo, x, v)


def ref_binary(params, topo, x, v):
    return ref.binary_force(params.bonds["binary"], topo.bonds["binary"], x, v)


def ref_activations(params, topo, x, v):
    return ref.neuron_activations(params.bonds["binary"], topo.bonds["binary"], x, v)


# --------------------------------------------------------------------------------------------
# The reference itself: forces are minus the gradient of the energy (finite differences)
# --------------------------------------------------------------------------------------------


def _numerical_gradient(fun, x, eps=1e-6):
    grad = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        xp, xm = x.copy(), x.copy()
        xp[idx] += eps
        xm[idx] -= eps
        grad[idx] = (fun(xp) - fun(xm)) / (2 * eps)
    return grad


@pytest.mark.parametrize("dim", [2, 3])
def test_reference_conservative_forces_are_minus_energy_gradient(dim):
    params, topo, x, v = random_system(11 + dim, dim, neural=np.zeros(6, bool))
    params = replace(
        params,
        unary={"damping": np.zeros(topo.count("unary"))},
        binary={"damping": np.zeros(topo.count("binary"))},
    )
    expected = -_numerical_gradient(lambda y: float(ref.potential_energy(params, topo, y)), x)
    assert_close(ref.total_force(params, topo, x, v), expected, rtol=1e-7)
    # the ternary part alone, since its gradient is the least obvious one
    only_tern = replace(
        params,
        mass=np.zeros_like(params.mass),
        unary={"stiffness": np.zeros(topo.count("unary"))},
        binary={"stiffness": np.zeros(topo.count("binary"))},
    )
    expected = -_numerical_gradient(lambda y: float(ref.potential_energy(only_tern, topo, y)), x)
    assert_close(ref.kind_force("ternary", params, topo, x, v), expected, rtol=1e-7)


# --------------------------------------------------------------------------------------------
# Each force family against the reference
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("seed,dim", SYSTEMS)
@pytest.mark.parametrize("name,family", FAMILY_PAIRS, ids=[n for n, _ in FAMILY_PAIRS])
def test_family_matches_reference(name, family, seed, dim):
    params, topo, x, v = random_system(seed, dim)
    expected = ref_family(name, params, topo, x, v)
    assert np.abs(expected).max() > 1e-3  # not a vacuous comparison
    assert_close(family(params, topo, x, v), expected)


@pytest.mark.parametrize("seed,dim", SYSTEMS)
def test_neural_binary_matches_reference(seed, dim):
    """Every binary bond neural, random weights (non-zero diagonal), gains and thresholds."""
    params, topo, x, v = random_system(100 + seed, dim, neural=np.ones(6, bool))
    v = 0.3 * v  # keep most neurons off saturation
    # neurons alone: no spring, no damper, so the comparison is on the neural term only
    neural_only = replace(params, binary={"stiffness": np.zeros(6), "damping": np.zeros(6)})
    expected = ref_binary(neural_only, topo, x, v)
    assert np.abs(expected).max() > 1e-3
    assert_close(binary(neural_only, topo, x, v), expected)
    assert_close(binary(params, topo, x, v), ref_binary(params, topo, x, v))
    acts = ref_activations(params, topo, x, v)
    assert (np.abs(acts) < 0.95).sum() >= 3 and np.abs(acts).min() > 1e-6  # mostly unsaturated
    assert_close(neuron_activity(params, topo, x, v), acts)


@pytest.mark.parametrize("seed,dim", SYSTEMS)
def test_mixed_neural_and_plain_bonds_and_total_force(seed, dim):
    params, topo, x, v = random_system(200 + seed, dim)
    assert neural_of(topo).any() and not neural_of(topo).all()
    assert_close(binary(params, topo, x, v), ref_binary(params, topo, x, v))
    assert_close(total_force(params, topo, x, v), ref.total_force(params, topo, x, v))
    expected_acts = np.where(neural_of(topo), ref_activations(params, topo, x, v), 0.0)
    assert_close(neuron_activity(params, topo, x, v), expected_acts)


def test_neuron_ignores_its_own_bond():
    params, topo, x, v = random_system(7, 3, neural=np.ones(6, bool))
    w = params.bonds["binary"]
    bumped = replace(
        params,
        binary={
            "length_weights": w["length_weights"] + 50.0 * np.eye(6),
            "rate_weights": w["rate_weights"] - 50.0 * np.eye(6),
        },
    )
    assert_close(binary(bumped, topo, x, v), binary(params, topo, x, v), 1e-15)


def test_empty_families_give_zero_force():
    rng = np.random.default_rng(3)
    topo = random_topology(rng, 4, 3, n_unary=0, n_binary=0, n_ternary=0, neural=[])
    params = random_params(rng, topo)
    x, v = random_state(rng, 4, 3)
    for _, family in FAMILY_PAIRS[1:]:
        np.testing.assert_array_equal(family(params, topo, x, v), np.zeros((4, 3)))
    assert_close(total_force(params, topo, x, v), params.mass[:, None] * params.gravity)


# --------------------------------------------------------------------------------------------
# Rollouts in lockstep with the reference
# --------------------------------------------------------------------------------------------


def mixed_model_text(dim: int) -> str:
    """A model with every element: gravity, unary spring + damper, plain and neural binary
    bonds (random weights), ternary flexion springs."""
    rng = np.random.default_rng(40 + dim)
    names = ["a", "b", "c", "d", "e"]
    pos = np.array([[0, 0, 0], [0.5, 0.1, 0], [0.9, 0.4, 0.1], [0.4, 0.8, -0.1], [0.0, 0.5, 0.2]])
    pos = pos[:, :dim] + rng.normal(0.0, 0.02, (5, dim))
    vel = rng.normal(0.0, 0.3, (5, dim))

    def vec(a):
        return "[" + ", ".join(repr(float(y)) for y in a) + "]"

    lines = [
        f'name = "mixed{dim}d"',
        f"dimension = {dim}",
        f"gravity = {vec([0.3, -9.81, 0.5][:dim])}",
    ]
    for i, n in enumerate(names):
        lines += [
            "[[particle]]",
            f'name = "{n}"',
            f"mass = {0.5 + 0.3 * i}",
            f"position = {vec(pos[i])}",
            f"velocity = {vec(vel[i])}",
        ]
    lines += [
        "[[bond]]",
        'kind = "unary"',
        'particles = ["a"]',
        "stiffness = 300.0",
        "damping = 1.5",
        f"anchor = {vec([0.02, -0.01, 0.03][:dim])}",
    ]
    binary = [("a", "b"), ("b", "c"), ("c", "d"), ("d", "e"), ("e", "a"), ("b", "d")]
    neural = [False, True, False, True, True, False]
    for bi, ((p, q), is_neural) in enumerate(zip(binary, neural, strict=True)):
        rest = float(np.linalg.norm(pos[names.index(p)] - pos[names.index(q)])) * 0.95
        lines += [
            "[[bond]]",
            'kind = "binary"',
            f'particles = ["{p}", "{q}"]',
            f"stiffness = {80.0 + 20 * bi}",
            f"rest_length = {rest!r}",
            f"damping = {0.1 * bi}",
        ]
        if is_neural:
            w_len = [0.0 if j == bi else float(w) for j, w in enumerate(rng.uniform(-3, 3, 6))]
            w_rate = [0.0 if j == bi else float(w) for j, w in enumerate(rng.uniform(-1, 1, 6))]
            lines += [
                "neural = true",
                f"gain = {2.0 + bi}",
                f"threshold = {0.1 * bi - 0.2}",
                f"weights = {{ length = {vec(w_len)}, rate = {vec(w_rate)} }}",
            ]
    for bi, (p, q, r) in enumerate([("a", "b", "c"), ("b", "c", "d"), ("c", "d", "e")]):
        lines += [
            "[[bond]]",
            'kind = "ternary"',
            f'particles = ["{p}", "{q}", "{r}"]',
            f"stiffness = {3.0 + bi}",
            f"rest_angle = {1.8 + 0.3 * bi}",
        ]
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("substeps", [1, 3])
@pytest.mark.parametrize("method", ["euler", "verlet"])
def test_rollout_lockstep_with_reference(method, substeps, dim):
    model = loads_model(mixed_model_text(dim))
    topo, params = model.topology, model.params
    assert neural_of(topo).any() and topo.count("unary") and topo.count("ternary")
    assert params.gravity.any()
    x0, v0 = model.initial_state()
    dt, n = 2e-3, 200
    xs = np.asarray(rollout(params, topo, x0, v0, dt, n, substeps=substeps, method=method))
    expected = ref.rollout(params, topo, x0, v0, dt, n, substeps=substeps, method=method)
    assert xs.shape == expected.shape == (n, 5, dim)
    assert np.abs(expected[-1] - expected[0]).max() > 1e-2  # the system did move
    scale = np.abs(expected).max()
    np.testing.assert_allclose(xs, expected, rtol=0, atol=1e-12 * scale)


# --------------------------------------------------------------------------------------------
# Analytic results and conservation laws
# --------------------------------------------------------------------------------------------


def two_body(m1, m2, k, l0, dim=3):
    model = loads_model(
        f"""
dimension = {dim}
[[particle]]
name = "a"
mass = {m1!r}
[[particle]]
name = "b"
mass = {m2!r}
[[bond]]
kind = "binary"
particles = ["a", "b"]
stiffness = {k!r}
rest_length = {l0!r}
"""
    )
    return model.params, model.topology


def zero_crossings(t, y):
    s = np.flatnonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)
    return t[s] - y[s] * (t[s + 1] - t[s]) / (y[s + 1] - y[s])


@pytest.mark.parametrize("method", ["euler", "verlet"])
def test_two_body_spring_frequency(method, record_property):
    m1, m2, k, l0, stretch = 0.7, 1.9, 45.0, 0.8, 0.05
    params, topo = two_body(m1, m2, k, l0)
    mu = m1 * m2 / (m1 + m2)
    omega = math.sqrt(k / mu)
    period = 2 * math.pi / omega
    direction = np.array([0.48, -0.6, 0.64])
    x0 = np.array([[0.1, 0.2, 0.3], [0.1, 0.2, 0.3]]) + np.outer([0.0, 1.0], direction) * (
        l0 + stretch
    )
    v0 = np.tile([0.3, -0.1, 0.2], (2, 1))  # a common drift: no relative transverse motion
    dt = period / 1000
    n = 5 * 1000 + 1
    xs = np.asarray(rollout(params, topo, x0, v0, dt, n, method=method))
    e = np.linalg.norm(xs[:, 1] - xs[:, 0], axis=-1) - l0
    assert np.abs(e).max() == pytest.approx(stretch, rel=1e-2)
    crossings = zero_crossings(dt * np.arange(n), e)
    assert len(crossings) >= 9
    measured = 2 * (crossings[-1] - crossings[0]) / (len(crossings) - 1)
    error = abs(2 * math.pi / measured - omega) / omega
    record_property("relative_frequency_error", float(error))
    print(f"{method}: omega={omega:.6f}, relative frequency error {error:.2e}")
    assert error < 5e-3


def conservative_system(dim=3, seed=5):
    """Binary + ternary springs only (no dampers, neurons, gravity or unary bonds)."""
    rng = np.random.default_rng(seed)
    topo = random_topology(
        rng, 5, dim, n_unary=0, n_binary=6, n_ternary=3, neural=np.zeros(6, bool)
    )
    params = random_params(rng, topo)
    x, v = random_state(rng, 5, dim, min_distance=0.4)
    pairs = topo.particles("binary")
    lengths = np.linalg.norm(x[pairs[:, 1]] - x[pairs[:, 0]], axis=-1)
    params = replace(
        params,
        gravity=np.zeros(dim),
        binary={
            "damping": np.zeros(6),
            "rest_length": lengths * rng.uniform(0.9, 1.1, 6),
            "stiffness": rng.uniform(20.0, 60.0, 6),
        },
        ternary={"stiffness": rng.uniform(1.0, 3.0, 3)},
    )
    return params, topo, x, 0.3 * v


def test_verlet_energy_band_without_drift(record_property):
    params, topo, x0, v0 = conservative_system(seed=6)
    dt, n = 2e-3, 10_000
    xs, vs = rollout_states(params, topo, x0, v0, dt, n, method="verlet")
    energy = ref.energy(params, topo, np.asarray(xs), np.asarray(vs))
    e0 = float(ref.energy(params, topo, x0, v0))
    first, last = energy[:1000], energy[-1000:]
    band_first = float(first.max() - first.min())
    band_last = float(last.max() - last.min())
    shift = abs(float(last.mean() - first.mean()))
    worst = float(np.abs(energy - e0).max())
    for key, value in [
        ("energy_band_first_rel", band_first / e0),
        ("energy_band_last_rel", band_last / e0),
        ("energy_mean_shift_rel", shift / e0),
        ("energy_max_deviation_rel", worst / e0),
    ]:
        record_property(key, float(value))
        print(f"{key} = {value:.2e}")
    # the dynamics are not trivial: energy moves between kinetic and potential
    kinetic = ref.kinetic_energy(params, np.asarray(vs))
    assert kinetic.max() - kinetic.min() > 0.2 * e0
    assert worst < 1e-4 * e0  # a bounded band, O(h^2) wide
    # no drift: the last thousand steps sit where the first thousand did, in a band of the same
    # width (the width itself fluctuates by ~2x with the phases of the normal modes)
    assert shift < 0.5 * band_first
    assert band_last < 3 * band_first


@functools.cache
def _integrate_to(method):
    """A jitted fixed-time integration with the package's step, n steps of h (both traced)."""
    step = {"euler": euler_step, "verlet": verlet_step}[method]

    @jax.jit
    def run(params, x0, v0, h, n):
        def body(_, state):
            return step(params, CONVERGENCE_TOPOLOGY, *state, h)

        return jax.lax.fori_loop(0, n, body, (jnp.asarray(x0), jnp.asarray(v0)))[0]

    return run


def convergence_system():
    params, topo, x0, v0 = conservative_system(seed=9)
    # conservative unary springs and gravity too
    rng = np.random.default_rng(1)
    bonds = {**topo.bonds, "unary": {"particles": np.array([[0], [3]], np.int32)}}
    topo = dataclasses.replace(topo, bonds=bonds)
    params = replace(
        params,
        gravity=np.array([0.0, -9.81, 1.0]),
        unary={
            "stiffness": np.array([30.0, 10.0]),
            "damping": np.zeros(2),
            "anchor": x0[[0, 3]] + rng.normal(0.0, 0.05, (2, 3)),
            "anchor_velocity": np.zeros((2, 3)),  # a moving anchor does work: not conservative
        },
    )
    return params, topo, x0, v0


CONVERGENCE_TOPOLOGY = convergence_system()[1]


@pytest.mark.parametrize("method,order", [("euler", 1), ("verlet", 2)])
def test_convergence_order(method, order, record_property):
    params, topo, x0, v0 = convergence_system()
    t_end = 0.5
    ns = np.array([100, 200, 400, 800, 1600] if method == "euler" else [50, 100, 200, 400, 800])
    n_exact = 64 * 800
    exact = np.asarray(_integrate_to("verlet")(params, x0, v0, t_end / n_exact, n_exact))
    assert np.abs(exact - x0).max() > 0.05
    run = _integrate_to(method)
    errors = np.array(
        [np.abs(np.asarray(run(params, x0, v0, t_end / n, n)) - exact).max() for n in ns]
    )
    # the same numbers through rollout (scan), for the coarsest step
    xs = rollout(params, topo, x0, v0, t_end / ns[0], ns[0] + 1, method=method)
    np.testing.assert_allclose(np.abs(np.asarray(xs[-1]) - exact).max(), errors[0], rtol=1e-9)
    slope = np.polyfit(np.log(t_end / ns), np.log(errors), 1)[0]
    record_property("order", float(slope))
    print(f"{method}: errors {errors}, fitted order {slope:.3f}")
    assert abs(slope - order) < 0.2


def cross(a, b):
    """a × b over the last axis; a scalar (the z component) in 2D."""
    if a.shape[-1] == 2:
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return np.cross(a, b)


def momentum_and_angular_momentum(params, xs, vs):
    """sum_p m_p v_p and sum_p m_p x_p × v_p for states [N, P, D]."""
    m = np.asarray(params.mass)
    momentum = np.einsum("p,npd->nd", m, vs)
    angular = np.tensordot(cross(xs, vs), m, axes=([1], [0]))
    return momentum, angular


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("method", ["euler", "verlet"])
def test_internal_forces_conserve_momentum(method, dim):
    """Binary (viscoelastic and neural) and ternary forces only: no external force."""
    params, topo, x0, v0 = random_system(300 + dim, dim, n_unary=0)
    assert neural_of(topo).any()
    params = replace(params, gravity=np.zeros(dim))
    # a quick sanity check at the initial state: internal forces cancel
    f = np.asarray(total_force(params, topo, x0, v0))
    np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-12 * np.abs(f).max())
    xs, vs = rollout_states(params, topo, x0, v0, 1e-3, 500, method=method)
    xs, vs = np.concatenate([x0[None], xs]), np.concatenate([v0[None], vs])
    p, angular = momentum_and_angular_momentum(params, xs, vs)
    assert np.abs(vs[-1] - v0).max() > 0.1  # velocities did change
    np.testing.assert_allclose(p, np.broadcast_to(p[0], p.shape), rtol=0, atol=1e-10)
    # central and flexion forces exert no torque, and both integrators keep sum m x × v exactly
    np.testing.assert_allclose(
        angular, np.broadcast_to(angular[0], angular.shape), rtol=0, atol=1e-10
    )


@pytest.mark.parametrize("seed,dim", SYSTEMS)
def test_ternary_forces_sum_to_zero_without_torque(seed, dim):
    params, topo, x, v = random_system(400 + seed, dim)
    for kind in ("ternary", "binary"):
        f = np.asarray(forces.bond_forces(kind, params, topo, x, v))
        scale = np.abs(f).max() * np.abs(x).max()
        assert scale > 1e-3
        np.testing.assert_allclose(f.sum(axis=0), 0.0, atol=1e-13 * scale)
        torque = cross(x, f).sum(axis=0)
        np.testing.assert_allclose(torque, 0.0, atol=1e-13 * scale)
        # also about another origin
        torque = cross(x - np.arange(1, dim + 1), f).sum(axis=0)
        np.testing.assert_allclose(torque, 0.0, atol=1e-12 * scale)


# --------------------------------------------------------------------------------------------
# Population vectorisation
# --------------------------------------------------------------------------------------------


def test_vmap_total_force_matches_loop():
    rng = np.random.default_rng(21)
    topo = random_topology(rng, 6, 3)
    population = [random_params(rng, topo) for _ in range(8)]
    stacked = jax.tree_util.tree_map(lambda *a: np.stack(a), *population)
    x, v = random_state(rng, 6, 3)
    xs = np.stack([random_state(rng, 6, 3)[0] for _ in range(8)])
    vs = rng.normal(0.0, 1.0, xs.shape)

    one = jax.jit(lambda p, y, w: total_force(p, topo, y, w))
    shared = jax.jit(jax.vmap(lambda p: total_force(p, topo, x, v)))(stacked)
    per_state = jax.jit(jax.vmap(one))(stacked, xs, vs)
    for n, p in enumerate(population):
        assert_close(shared[n], one(p, x, v), 1e-13)
        assert_close(per_state[n], one(p, xs[n], vs[n]), 1e-13)
        assert_close(per_state[n], ref.total_force(p, topo, xs[n], vs[n]))


@pytest.mark.parametrize("example", ["horse_limb", "chain2d", "triangle"])
def test_vmap_over_decoded_genomes_matches_loop(example):
    model = load_model(EXAMPLES / f"{example}.toml")
    layout, topo = model.layout, model.topology
    assert layout.n_genes >= 5
    rng = np.random.default_rng(5)
    genomes = rng.uniform(layout.lower, layout.upper, (6, layout.n_genes))
    x, v = random_state(rng, topo.n_particles, topo.dimension)

    def force(g):
        return total_force(layout.decode(g), topo, x, v)

    batched = jax.jit(jax.vmap(force))(jnp.asarray(genomes))
    one = jax.jit(force)
    decode = jax.jit(layout.decode)
    for n, g in enumerate(genomes):
        expected = one(jnp.asarray(g))
        assert_close(batched[n], expected, 1e-13)
        p = jax.tree_util.tree_map(np.asarray, decode(jnp.asarray(g)))
        assert_close(expected, ref.total_force(p, topo, x, v))
