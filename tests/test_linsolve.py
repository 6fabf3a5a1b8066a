"""The integrator's small dense solves (:mod:`activebonds.physics.linsolve`): LAPACK's
numbers and derivatives, no LAPACK call in the integrator's programs, and no hang where
jaxlib 0.10's LAPACK kernels hung (two batched solves running at once on XLA's CPU threads)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from activebonds.model import loads_model
from activebonds.physics import start_velocity
from activebonds.physics.linsolve import solve

CONTACTS = """
name = "pair"
dimension = 3
gravity = [0.0, 0.0, -9.81]

[[particle]]
name = "a"
position = [0.0, 0.0, 0.01]
velocity = [1.2, 0.9, -0.3]

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
for _p in ("a", "b"):
    CONTACTS += f"""
[[bond]]
kind = "contact"
type = "ground"
particles = ["{_p}"]
normal = [0.0, 0.0, 1.0]
stiffness = 3000.0
damping = 8.0
friction = 0.6
"""


@pytest.mark.parametrize("n", [2, 3, 15, 40])
def test_solve_matches_lapack_and_its_derivatives(n):
    rng = np.random.default_rng(n)
    a = rng.standard_normal((20, n, n))
    a[:, 0, 0] = 0.0  # a zero first pivot: the rows must be exchanged
    b = rng.standard_normal((20, n))
    x = np.asarray(jax.vmap(solve)(a, b))
    np.testing.assert_allclose(x, np.linalg.solve(a, b[..., None])[..., 0], rtol=1e-10, atol=0)
    da, db = rng.standard_normal((n, n)), rng.standard_normal(n)
    _, tangent = jax.jvp(solve, (a[1], b[1]), (da, db))
    _, expected = jax.jvp(jnp.linalg.solve, (a[1], b[1]), (da, db))
    np.testing.assert_allclose(tangent, expected, rtol=1e-10, atol=1e-12)

    if n > 3:
        return

    def second(f):  # forward over forward: the implicit kicks' D x D solves inside the
        # Newton start velocity's Jacobian, inside a Jacobian over the parameters
        return jax.jacfwd(lambda m: jax.jacfwd(f, argnums=1)(m, b[1]).sum())(a[1])

    np.testing.assert_allclose(second(solve), second(jnp.linalg.solve), rtol=1e-9, atol=1e-12)


def test_a_singular_system_gives_non_finite_values_as_lapack():
    assert not np.isfinite(np.asarray(solve(jnp.zeros((3, 3)), jnp.ones(3)))).any()


def _lowered(fn, *args) -> str:
    return jax.jit(fn).lower(*args).as_text()


def test_the_integrators_programs_call_no_lapack():
    model = loads_model(CONTACTS)
    params, topo = model.params, model.topology
    x0, v0 = (jnp.asarray(s) for s in model.initial_state())
    x1 = x0 + 0.01 * v0
    starts = (jnp.stack([x0, x0]), jnp.stack([x1, x1]))

    def stiff_start(params, a, b):  # Newton on the landing, the kicks implicit
        return jax.vmap(lambda p, q: start_velocity(params, topo, p, q, 0.01, 3, "verlet"))(a, b)

    def newton_start(params, a, b):  # the implicitly differentiated Newton (no contacts)
        free = model.without({"contact"})
        return jax.vmap(
            lambda p, q: start_velocity(params, free.topology, p, q, 0.01, 3, "verlet", newton=True)
        )(a, b)

    for fn in (stiff_start, newton_start):
        text = _lowered(jax.jacfwd(fn), params, *starts)
        assert "lapack" not in text, fn.__name__
    assert "lapack" in _lowered(jnp.linalg.solve, jnp.eye(3), jnp.ones(3))  # the check sees it


def _two_solves_a_round(solver, rounds: int = 20, length: int = 40):
    """Two independent batched 15 x 15 solves a round of a loop of ``length`` rounds, run
    ``rounds`` times."""
    rng = np.random.default_rng(0)
    n, size = 2000, 15
    a1, a2 = (rng.standard_normal((n, size, size)) + 5 * np.eye(size) for _ in range(2))
    b = rng.standard_normal((n, size))

    @jax.jit
    def run(a1, a2, b):
        def body(_, state):
            x, y = state
            return jax.vmap(solver)(a1, x), jax.vmap(solver)(a2, y)

        return jax.lax.fori_loop(0, length, body, (b, b))

    for i in range(rounds):
        x, y = run(a1, a2, b + i)
        assert np.isfinite(np.asarray(x)).all() and np.isfinite(np.asarray(y)).all()


@pytest.mark.timeout(120)
def test_two_batched_solves_at_once_finish():
    """The start velocity's Newton steps are such solves (P D unknowns, vmapped over frames
    and a population). On two cores, jaxlib 0.10's LAPACK solve (``jnp.linalg.solve``) hung
    in this loop (each call holding one of XLA's threads while it waited for the pieces of
    its batch, queued behind the other): in 2 of 6 runs of this test's size, and in 6 of 6
    runs of a script repeating it up to 300 times; a hang fails the test at its timeout."""
    _two_solves_a_round(solve)
