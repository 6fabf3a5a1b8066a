"""Contact bonds (a particle against a plane, DESIGN.md §2): forces against the NumPy oracle,
the physics they must reproduce (rest penetration, Coulomb stopping distance, a belt, energy
of an undamped bounce), bad input on the command line, and recovery by ``fit``."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import reference_numpy as ref
from activebonds import fit
from activebonds.bonds.contact import FRICTION_EPS
from activebonds.model import dumps_model, loads_model
from activebonds.physics import bond_forces, rollout_states, total_force
from activebonds.simulation import simulate
from helpers import cli, each_case_both_ways

G = 9.81


def one_particle(
    z0=0.0, vx=0.0, *, mass=1.0, k=1e4, c=50.0, mu=0.0, surface="[0.0, 0.0, 0.0]"
) -> str:
    """A particle above (z0 > 0) or in (z0 < 0) the ground z = 0, under gravity."""
    return f"""
name = "drop"
dimension = 3
gravity = [0.0, 0.0, {-G!r}]

[[particle]]
name = "p"
mass = {mass!r}
position = [0.0, 0.0, {z0!r}]
velocity = [{vx!r}, 0.0, 0.0]

[[bond]]
kind = "contact"
particles = ["p"]
normal = [0.0, 0.0, 1.0]
stiffness = {k!r}
damping = {c!r}
friction = {mu!r}
surface_velocity = {surface}
"""


# --------------------------------------------------------------------------------------------
# Forces against the oracle
# --------------------------------------------------------------------------------------------

# Tilted, unnormalised normals; a plane not through the origin; moving surfaces; free
# parameters with and without file bounds (the kind's default bounds).
ORACLE_3D = """
dimension = 3
gravity = [0.0, 0.0, -9.81]

[[particle]]
name = "a"
[[particle]]
name = "b"
mass = 2.0
[[particle]]
name = "c"
mass = 0.5

[[bond]]
kind = "contact"
type = "floor"
particles = ["a"]
normal = [0.3, -0.2, 1.0]
height = { value = 0.05 }
stiffness = { value = 1e4 }
damping = { value = 50.0, min = 0.0, max = 200.0 }
friction = { value = 0.8 }
surface_velocity = { value = [0.5, -0.2, 0.0] }

[[bond]]
kind = "contact"
type = "floor"
particles = ["b"]
normal = [0.3, -0.2, 1.0]
height = { value = 0.05 }
stiffness = { value = 1e4 }
damping = { value = 50.0, min = 0.0, max = 200.0 }
friction = { value = 0.8 }
surface_velocity = { value = [0.5, -0.2, 0.0] }

[[bond]]
kind = "contact"
particles = ["c"]
normal = [-1.0, 0.0, 0.0]
height = -0.2
stiffness = { value = 3e3, min = 1e2, max = 1e5 }
damping = 20.0
friction = { value = 0.3, min = 0.0, max = 1.5 }
surface_velocity = [0.0, 1.0, -0.5]

[[bond]]
kind = "contact"
particles = ["a"]
normal = [0.0, 1.0, 1.0]
stiffness = 500.0
"""

ORACLE_2D = """
dimension = 2
[[particle]]
name = "a"
[[particle]]
name = "b"
[[bond]]
kind = "contact"
particles = ["a"]
normal = [0.2, 1.0]
stiffness = { value = 2e3 }
damping = { value = 10.0 }
friction = { value = 0.6 }
surface_velocity = { value = [1.0, 0.0] }
[[bond]]
kind = "contact"
particles = ["b"]
normal = [1.0, -1.0]
height = 0.1
stiffness = 800.0
friction = 1.2
"""


def _cases(params, topo, x, v):
    """Per contact bond: below its plane, pushing (k d > c n.v), sliding (|vt| > eps)."""
    p, parts = params.bonds["contact"], topo.bonds["contact"]["particles"][:, 0]
    n = p["normal"]
    depth = p["height"] - np.sum(n * x[parts], axis=-1)
    push = p["stiffness"] * depth - p["damping"] * np.sum(n * v[parts], axis=-1)
    return depth > 0, (depth > 0) & (push > 0), (depth > 0) & (push <= 0)


@pytest.mark.parametrize("text", [ORACLE_3D, ORACLE_2D], ids=["3d", "2d"])
def test_contact_forces_match_the_oracle(text):
    model = loads_model(text)
    d = model.dimension
    rng = np.random.default_rng(7)
    lo, hi = model.layout.lower, model.layout.upper
    batched = jax.jit(
        jax.vmap(
            lambda g, x, v: (
                total_force(model.layout.decode(g), model.topology, x, v),
                bond_forces("contact", model.layout.decode(g), model.topology, x, v),
            )
        )
    )
    n_samples = 400
    genomes = rng.uniform(lo, hi, (n_samples, model.layout.n_genes))
    # states around the planes: about half the particles below theirs
    x = rng.uniform(-0.3, 0.3, (n_samples, model.topology.n_particles, d))
    v = rng.normal(0.0, 1.0, (n_samples, model.topology.n_particles, d))
    v[::10] *= 1e-4  # some near rest on the surface: |vt| ~ eps
    totals, contacts = (np.asarray(a) for a in batched(jnp.asarray(genomes), x, v))
    # the oracle's parameters: every genome decoded in one call (one by one: 6 s of dispatch)
    decoded = jax.jit(jax.vmap(model.layout.decode))(jnp.asarray(genomes))
    decoded = jax.tree_util.tree_map(np.asarray, decoded)
    seen = np.zeros(3, int)
    for s in range(n_samples):
        params = jax.tree_util.tree_map(lambda a, s=s: a[s], decoded)
        expected = ref.kind_force("contact", params, model.topology, x[s], v[s])
        np.testing.assert_allclose(contacts[s], expected, rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(
            totals[s], ref.total_force(params, model.topology, x[s], v[s]), rtol=1e-12, atol=1e-9
        )
        seen += [int(c.sum()) for c in _cases(params, model.topology, x[s], v[s])]
    below, pushing, clipped = seen
    n_bonds = n_samples * model.topology.count("contact")
    assert 0.3 * n_bonds < below < 0.7 * n_bonds  # above and below the plane
    assert pushing > 0.2 * n_bonds and clipped > 0.02 * n_bonds  # max(0, .) both ways
    assert np.abs(contacts).max() > 10.0  # the comparison is not of zeros


def test_contact_force_by_hand():
    """A particle 1 cm deep in a plane tilted 45 degrees, sliding on a moving surface."""
    text = """
dimension = 3
[[particle]]
name = "p"
[[bond]]
kind = "contact"
particles = ["p"]
normal = [0.0, 1.0, 1.0]
height = 0.0
stiffness = 1000.0
damping = 10.0
friction = 0.5
surface_velocity = [0.2, 0.0, 0.0]
"""
    model = loads_model(text)
    n = np.array([0.0, 1.0, 1.0]) / math.sqrt(2)
    x = (-0.01 * n)[None]
    v = np.array([[1.2, 0.1, -0.1]])  # n.v = 0; relative tangential velocity (1.0, 0.1, -0.1)
    f = np.asarray(total_force(model.params, model.topology, jnp.asarray(x), jnp.asarray(v)))
    fn = 1000.0 * 0.01
    vt = np.array([1.0, 0.1, -0.1])
    expected = fn * n - 0.5 * fn * vt / math.sqrt(vt @ vt + FRICTION_EPS**2)
    np.testing.assert_allclose(f[0], expected, rtol=1e-14)
    assert FRICTION_EPS == 1e-3
    above = np.asarray(total_force(model.params, model.topology, jnp.asarray(-x), jnp.asarray(v)))
    np.testing.assert_array_equal(above, 0.0)
    leaving = np.asarray(  # k d - c n.v < 0: no pull
        total_force(model.params, model.topology, jnp.asarray(x), jnp.asarray(v + 2.0 * n))
    )
    np.testing.assert_array_equal(leaving, 0.0)


def _central_differences(f, args, h):
    """The gradient of scalar ``f`` by central differences in each entry of each argument."""
    out = []
    for k, a in enumerate(args):
        a = np.asarray(a, np.float64)
        g = np.zeros_like(a)
        for i in np.ndindex(a.shape):
            step = np.zeros_like(a)
            step[i] = h
            plus = [*args[:k], a + step, *args[k + 1 :]]
            minus = [*args[:k], a - step, *args[k + 1 :]]
            g[i] = (float(f(*plus)) - float(f(*minus))) / (2 * h)
        out.append(g)
    return out


def test_contact_gradients_are_finite_at_the_switch_and_match_differences_away_from_it():
    model = loads_model(one_particle(mu=0.8, surface="[0.3, 0.0, 0.0]"))
    genes = jnp.asarray(model.layout.initial())

    def force_sum(x, v):
        return jnp.sum(total_force(model.layout.decode(genes), model.topology, x, v) ** 2)

    jac = jax.jit(jax.grad(force_sum, argnums=(0, 1)))
    value = jax.jit(force_sum)
    loaded = 0
    for z in (0.0, -1e-3, 1e-3):  # exactly on the plane, below, above
        for vx in (0.3, 0.0):  # at rest relative to the belt, and at rest
            x = jnp.array([[0.0, 0.0, z]])
            v = jnp.array([[vx, 0.0, 0.0]])
            gx, gv = (np.asarray(g) for g in jac(x, v))
            assert np.isfinite(gx).all() and np.isfinite(gv).all()
            if z == 0.0:  # the switch itself: the force has a kink, no derivative to compare
                continue
            # 1 mm from the plane and pushing (k d = 10 N against c n.v = 0), steps of 1e-7
            # stay on one side of the switch; the friction's smoothing scale is 1e-3 m/s
            nx, nv = _central_differences(value, (x, v), 1e-7)
            scale = max(np.abs(nx).max(), np.abs(nv).max(), 1.0)
            np.testing.assert_allclose(gx, nx, rtol=1e-6, atol=1e-7 * scale)
            np.testing.assert_allclose(gv, nv, rtol=1e-6, atol=1e-7 * scale)
            loaded += z < 0
            if z < 0:  # below the plane the force depends on the state: the test has teeth
                assert np.abs(gx).max() > 1e3 and np.abs(gv).max() > 1.0
    assert loaded == 2


def test_the_normal_is_a_constant_normalised_when_loaded_and_written_back_as_given():
    model = loads_model(ORACLE_3D)
    assert not any("normal" in g.name for g in model.layout.genes)
    normals = model.params.bonds["contact"]["normal"]
    np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1.0, rtol=1e-15)
    np.testing.assert_allclose(normals[0], np.array([0.3, -0.2, 1.0]) / math.sqrt(1.13))
    assert (np.asarray(model.layout.index.bonds["contact"]["normal"]) == -1).all()
    genes = {g.name: g for g in model.layout.genes}  # default bounds where the file gives none
    assert (genes["type:floor.height"].lower, genes["type:floor.height"].upper) == pytest.approx(
        (-0.05, 0.15)
    )
    assert (genes["type:floor.friction"].lower, genes["type:floor.friction"].upper) == (0.0, 2.0)
    assert (genes["type:floor.stiffness"].lower, genes["type:floor.stiffness"].upper) == (
        pytest.approx(100.0),
        pytest.approx(1e6),
    )
    assert genes["type:floor.surface_velocity[1]"].lower == pytest.approx(-1.2)
    changed = model.with_genome(model.layout.initial() * 0.9)
    again = loads_model(dumps_model(changed))
    assert again.spec.bond[0].normal == [0.3, -0.2, 1.0]
    np.testing.assert_array_equal(again.params.bonds["contact"]["normal"], normals)
    for field in ("height", "damping", "friction", "surface_velocity"):
        np.testing.assert_allclose(
            again.params.bonds["contact"][field], changed.params.bonds["contact"][field]
        )


# --------------------------------------------------------------------------------------------
# Physics
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("integrator", ["euler", "verlet"])
def test_a_dropped_particle_rests_at_m_g_over_k(integrator):
    mass, k = 2.0, 1e4
    model = loads_model(one_particle(0.05, mass=mass, k=k, c=60.0))
    traj = simulate(model, n_frames=601, rate=200.0, substeps=10, integrator=integrator)
    z = traj.positions[:, 0, 2]
    first_contact = int(np.argmax(z < 0))
    assert first_contact > 0 and (z[first_contact:] > 0).any()  # it bounced off the plane
    penetration = -z[-1]
    expected = mass * G / k
    assert abs(penetration - expected) / expected < 1e-6
    assert np.abs(np.diff(z[-20:])).max() < 1e-12  # at rest


@pytest.mark.parametrize("integrator", ["euler", "verlet"])
def test_friction_stops_a_sliding_particle_at_v0_squared_over_2_mu_g(integrator):
    mass, k, mu, v0 = 1.5, 1e4, 0.5, 1.0
    rest = -mass * G / k  # pressed by gravity at its equilibrium penetration
    model = loads_model(one_particle(rest, v0, mass=mass, k=k, mu=mu))
    traj = simulate(model, n_frames=121, rate=200.0, substeps=10, integrator=integrator)
    x = traj.positions[:, 0, 0]
    expected = v0**2 / (2 * mu * G)  # 0.1019 m, for |vt| >> eps
    assert abs(x[-1] - expected) / expected < 0.01
    assert np.abs(np.diff(x[-10:])).max() < 1e-6  # stopped (0.6 s; it stops at 0.2 s)
    np.testing.assert_allclose(traj.positions[:, 0, 2], rest, rtol=1e-9)  # stayed pressed


def test_a_belt_drags_a_particle_to_its_speed():
    """At rest on a belt moving at s: friction accelerates it at mu g for s / (mu g) seconds
    (slipping s^2 / (2 mu g) behind the belt), then it rides with the belt."""
    mass, k, mu, s = 1.0, 1e4, 0.4, 0.8
    rest = -mass * G / k
    model = loads_model(one_particle(rest, mass=mass, k=k, mu=mu, surface=f"[{s}, 0.0, 0.0]"))
    traj = simulate(model, n_frames=161, rate=200.0, substeps=10, integrator="verlet")
    t = traj.times - traj.times[0]
    x = traj.positions[:, 0, 0]
    riding = t > s / (mu * G) + 0.05
    lag = s * t[riding] - x[riding]
    np.testing.assert_allclose(lag, s**2 / (2 * mu * G), rtol=0.01)
    np.testing.assert_allclose(np.diff(x[riding]) / traj.dt, s, rtol=1e-3)


def _energy_band(h: float, seconds: float = 1.5) -> float:
    model = loads_model(one_particle(0.05, vx=0.3, c=0.0, mu=0.0))
    x0, v0 = model.initial_state()
    n = int(round(seconds / h))
    xs, vs = rollout_states(
        model.params, model.topology, jnp.asarray(x0), jnp.asarray(v0), h, n, 1, "verlet"
    )
    xs, vs = np.asarray(xs), np.asarray(vs)
    bounces = int(np.sum(np.diff((xs[:, 0, 2] < 0).astype(int)) == 1))
    assert bounces >= 5  # several contacts, each entered and left
    # kinetic + gravitational + 1/2 k d^2 while in contact (reference_numpy's contact energy)
    e0 = ref.energy(model.params, model.topology, x0, v0)
    energy = ref.energy(model.params, model.topology, xs, vs)
    return float(np.abs(energy - e0).max() / e0)


def test_energy_of_an_undamped_bounce_stays_in_a_band_that_shrinks_with_dt():
    bands = [_energy_band(h) for h in (1e-3, 5e-4, 2.5e-4)]
    # measured: 2.2e-3, 6.0e-4, 1.5e-4 relative (about h^2; no drift over the bounces)
    assert bands[0] < 5e-3
    assert bands[1] < bands[0] / 3 and bands[2] < bands[1] / 3


# --------------------------------------------------------------------------------------------
# Bad input: one line each, exit 2
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    *each_case_both_ways(
        "old, new, message",
        [
            (
                "normal = [0.0, 0.0, 1.0]",
                "normal = [0.0, 0.0, 0.0]",
                "bond[0].normal: must be a non-zero vector",
            ),
            (
                'particles = ["p"]',
                'particles = ["p", "q"]',
                "bond[0].particles: a contact bond needs 1 particle name(s), got 2",
            ),
            ("friction = 0.5", "friction = -0.5", "bond[0].friction: must be >= 0, got -0.5"),
            (
                "normal = [0.0, 0.0, 1.0]",
                "normal = [0.0, 1.0]",
                "bond[0].normal: expected 3 components, got 2",
            ),
        ],
        ids=["zero-normal", "two-particles", "negative-friction", "normal-length"],
    )
)
def test_bad_contact_bonds_are_refused_by_the_cli(tmp_path, run, old, new, message):
    text = one_particle(mu=0.5) + '\n[[particle]]\nname = "q"\n'
    assert text.count(old) == 1
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new), encoding="utf-8")
    out = tmp_path / "out.csv"
    proc = run("simulate", path, "--n-frames", "5", "--rate", "100", "--out", out)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert str(path) in lines[0] and message in lines[0], lines[0]
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# Recovery: a two-particle hopper on a moving belt
# --------------------------------------------------------------------------------------------

TRUTH = {"stiffness": 3000.0, "damping": 8.0, "friction": 0.6, "belt": 0.4}


def hopper(stiffness, damping, friction, belt) -> str:
    contact = """
[[bond]]
kind = "contact"
type = "ground"
particles = ["{p}"]
normal = [0.0, 0.0, 1.0]
stiffness = {{ value = {k!r}, min = 2e2, max = 2e4 }}
damping = {{ value = {c!r}, min = 0.0, max = 50.0 }}
friction = {{ value = {mu!r}, min = 0.0, max = 2.0 }}
surface_velocity = {{ value = [{s!r}, 0.0, 0.0], min = [-1.0, -1.0, -0.01], max = [1.0, 1.0, 0.01] }}
"""
    text = """
name = "hopper"
dimension = 3
gravity = [0.0, 0.0, -9.81]

[[particle]]
name = "a"
position = [0.0, 0.0, 0.12]
velocity = [1.2, 0.9, 0.0]

[[particle]]
name = "b"
mass = 1.5
position = [0.3, 0.0, 0.25]
velocity = [0.2, -0.8, 0.6]

[[bond]]
kind = "binary"
particles = ["a", "b"]
stiffness = 150.0
rest_length = 0.35
damping = 0.5
"""
    for p in ("a", "b"):
        text += contact.format(p=p, k=stiffness, c=damping, mu=friction, s=belt)
    return text


@pytest.mark.parametrize(
    "integrator",
    ["euler", pytest.param("verlet", marks=pytest.mark.slow)],  # integration scale: slow
)
def test_contact_parameters_are_recovered_by_fit(integrator):
    truth = loads_model(hopper(**TRUTH))
    data = simulate(truth, n_frames=200, rate=200.0, integrator=integrator)
    z = data.positions[:, :, 2]
    assert ((z < 0).sum(axis=0) > 20).all() and ((z > 0.05).sum(axis=0) > 20).all()  # hops
    start = loads_model(hopper(1000.0, 20.0, 1.0, 0.0))
    result = fit(
        start,
        data,
        population=40,
        generations=300,
        seed=0,
        init="uniform",
        integrator=integrator,
        refine="none",
    )
    found = result.model.params.bonds["contact"]
    got = {
        "stiffness": found["stiffness"][0],
        "damping": found["damping"][0],
        "friction": found["friction"][0],
        "belt": found["surface_velocity"][0, 0],
    }
    for name, value in TRUTH.items():
        assert abs(got[name] - value) / value < 0.02, (name, got[name], value)
    assert abs(found["surface_velocity"][0, 1]) < 0.02 * TRUTH["belt"]  # the belt runs along x


@pytest.mark.slow
def test_simulate_fit_and_report_a_contact_model_on_the_command_line(tmp_path):
    """The commands end to end on a model with contact bonds (about 40 s: three processes)."""
    model = tmp_path / "hopper.toml"
    model.write_text(hopper(**TRUTH), encoding="utf-8")
    data, run = tmp_path / "hop.csv", tmp_path / "RUN"
    proc = cli("simulate", model, "--n-frames", "200", "--rate", "200", "--out", data)
    assert proc.returncode == 0, proc.stderr
    proc = cli("fit", model, data, "--out", run, "--population", "20", "--generations", "20")
    assert proc.returncode == 0, proc.stderr
    best = loads_model((run / "best_model.toml").read_text(encoding="utf-8"))
    assert best.topology.count("contact") == 2
    assert best.spec.bond[1].normal == [0.0, 0.0, 1.0]
    proc = cli("report", run)
    assert proc.returncode == 0, proc.stderr
    html = (run / "report.html").read_text(encoding="utf-8")
    assert "type:ground.friction" in html and "type:ground.surface_velocity[0]" in html
