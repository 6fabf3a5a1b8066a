"""The structured shooting solver (identify/solvers/shooting_normal.py, identify/solvers/lm.py) against the
dense reference: the normal equations by block equal J^T J and J^T r of the whole Jacobian,
the block-tridiagonal recursion equals a dense solve, the Schur complement is the parameters'
marginal information, and the structured Levenberg-Marquardt ends where optimistix's does."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

import activebonds
from activebonds.data import Trajectory
from activebonds.identify.costs.shooting import (
    frame_states,
    make_shooting,
    shooting_windows,
    start_states,
)
from activebonds.identify.judge.uncertainty import estimate
from activebonds.identify.problem import identification
from activebonds.identify.settings import FitSettings
from activebonds.identify.solvers.refine import Bounded, Refinement
from activebonds.identify.solvers.shooting_normal import (
    FLOOR,
    block_tridiagonal_solve,
    curvature,
    damped_step,
    make_normal,
    marginal_information,
    marquardt_diagonal,
)
from activebonds.model import load_model
from helpers import EXAMPLES


@pytest.fixture(scope="module")
def problem():
    """The triangle, 41 frames with 0.5 mm noise, windows of 8 frames, 2 Verlet substeps;
    the dense Jacobian of the shooting residuals over (u, X, V) and the blocks' normal."""
    model = load_model(EXAMPLES / "triangle.toml")
    clean = activebonds.simulate(model, 41, 60.0)
    rng = np.random.default_rng(3)
    traj = clean.with_positions(clean.positions + rng.normal(0, 5e-4, clean.positions.shape))
    windows = shooting_windows(traj.positions, traj.mask, traj.dt, 8)
    windows = type(windows)(  # one link cut, as between two recordings
        windows.starts,
        windows.target,
        windows.weight,
        windows.dt,
        link=np.array([1.0, 0.0, 1.0, 1.0]),
        segments=windows.segments,
    )
    x0, v0 = start_states(windows, [frame_states(traj.positions, traj.mask, traj.dt)])
    bounded = Bounded(model.layout.lower, model.layout.upper)
    u = jnp.asarray(bounded.from_genome(model.layout.initial())) + 0.05
    residuals, _ = make_shooting(model, windows, 2, "verlet")
    k = x0.shape[0]

    def flat(z):
        uu, s = z[: u.size], z[u.size :].reshape(k, -1)
        half = s.shape[1] // 2
        tree = residuals(
            bounded.to_genome(uu), (s[:, :half].reshape(x0.shape), s[:, half:].reshape(x0.shape))
        )
        return ravel_pytree(tree)[0]

    s = jnp.concatenate([jnp.asarray(x0).reshape(k, -1), jnp.asarray(v0).reshape(k, -1)], 1)
    z = jnp.concatenate([u, s.ravel()])
    jac = np.asarray(jax.jit(jax.jacfwd(flat))(z))  # compiled, not op by op
    r = np.asarray(jax.jit(flat)(z))
    normal = make_normal(model, windows, 2, "verlet", bounded.to_genome)(u, s)
    return {
        "jac": jac,
        "r": r,
        "normal": normal,
        "p": u.size,
        "k": k,
        "n": s.shape[1],
        "build": lambda: make_normal(model, windows, 2, "verlet", bounded.to_genome)(u, s),
    }


def _dense_normal(normal, p, k, n):
    """J^T J and J^T r assembled from the blocks, in the order (u, s_0, ..., s_K-1)."""
    size = p + k * n
    a = np.zeros((size, size))
    a[:p, :p] = normal.params
    for i in range(k):
        sl = slice(p + i * n, p + (i + 1) * n)
        a[sl, sl] = normal.diag[i]
        a[:p, sl] = np.asarray(normal.cross[i]).T
        a[sl, :p] = normal.cross[i]
        if i < k - 1:
            nxt = slice(p + (i + 1) * n, p + (i + 2) * n)
            a[sl, nxt] = normal.off[i]
            a[nxt, sl] = np.asarray(normal.off[i]).T
    g = np.concatenate([normal.grad_u, np.ravel(normal.grad_s)])
    return a, g


def test_the_blocks_are_the_dense_normal_equations(problem):
    a, g = _dense_normal(problem["normal"], problem["p"], problem["k"], problem["n"])
    jac, r = problem["jac"], problem["r"]
    scale = np.abs(jac.T @ jac).max()
    np.testing.assert_allclose(a, jac.T @ jac, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(g, jac.T @ r, rtol=0, atol=1e-10 * np.abs(jac.T @ r).max())


def test_windows_mapped_in_padded_equal_batches_give_the_same_blocks(problem, monkeypatch):
    """5 windows, at most 2 at a time: 3 batches of 2, the last padded with a copy of the last
    window (dropped), rather than a remainder batch traced and compiled as a second program."""
    from activebonds.identify.solvers import shooting_normal

    assert shooting_normal._batches(5, 2) == (2, 6)
    assert shooting_normal._batches(40, 24) == (20, 40)  # the tetrahedron's: no padding
    monkeypatch.setattr(shooting_normal, "LANES", 2 * (problem["n"] + problem["p"]))
    padded = problem["build"]()
    for a, b in zip(padded, problem["normal"], strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


def test_the_damped_step_is_the_dense_solve(problem):
    p, k, n = problem["p"], problem["k"], problem["n"]
    a, g = _dense_normal(problem["normal"], p, k, n)
    for damping in (1e-3, 1.0, 1e3):
        want = np.linalg.solve(a + damping * np.eye(len(g)), -g)
        du, ds = damped_step(problem["normal"], damping)
        got = np.concatenate([du, np.ravel(ds)])
        np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9 * np.abs(want).max())


def test_the_step_damped_by_marquardts_diagonal_is_the_dense_solve(problem):
    p, k, n = problem["p"], problem["k"], problem["n"]
    a, g = _dense_normal(problem["normal"], p, k, n)
    scale = np.maximum(np.diag(a), FLOOR * np.diag(a).max())  # J^T J's diagonal, floored
    du_scale, ds_scale = marquardt_diagonal(problem["normal"])
    np.testing.assert_allclose(np.concatenate([du_scale, np.ravel(ds_scale)]), scale, rtol=1e-12)
    for damping in (1e-3, 1.0, 1e3):
        want = np.linalg.solve(a + damping * np.diag(scale), -g)
        du, ds = damped_step(problem["normal"], (damping * du_scale, damping * ds_scale))
        got = np.concatenate([du, np.ravel(ds)])
        np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9 * np.abs(want).max())


def test_block_tridiagonal_solve_matches_a_dense_solve():
    rng = np.random.default_rng(0)
    k, n, r = 6, 4, 3
    blocks = rng.normal(size=(k, 2 * n, n))
    diag = np.einsum("kij,kil->kjl", blocks, blocks) + 4 * np.eye(n)
    off = rng.normal(size=(k - 1, n, n)) * 0.5
    dense = np.zeros((k * n, k * n))
    for i in range(k):
        dense[i * n : (i + 1) * n, i * n : (i + 1) * n] = diag[i]
        if i < k - 1:
            dense[i * n : (i + 1) * n, (i + 1) * n : (i + 2) * n] = off[i]
            dense[(i + 1) * n : (i + 2) * n, i * n : (i + 1) * n] = off[i].T
    assert np.all(np.linalg.eigvalsh(dense) > 0)
    rhs = rng.normal(size=(k, n, r))
    got = block_tridiagonal_solve(jnp.asarray(diag), jnp.asarray(off), jnp.asarray(rhs))
    want = np.linalg.solve(dense, rhs.reshape(k * n, r)).reshape(k, n, r)
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def test_the_schur_complement_is_the_parameters_marginal_information(problem):
    """Its inverse is the parameters' block of (J^T J)^-1: the covariance with the window
    states as nuisance variables."""
    p = problem["p"]
    jac = problem["jac"]
    r_inv = np.linalg.inv(np.linalg.qr(jac)[1])
    full_cov = (r_inv @ r_inv.T)[:p, :p]
    got = np.linalg.inv(np.asarray(marginal_information(problem["normal"])))
    np.testing.assert_allclose(got, full_cov, rtol=1e-6)


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_structured_and_dense_levenberg_marquardt_end_at_the_same_parameters():
    """0.5 mm of noise on the triangle, windows of 10 frames: both paths from the same start
    end within 0.05 standard deviations in every parameter (the structured path stops there,
    lm.PRECISION; optimistix's runs on to its Cauchy test) and at the same cost."""
    model = load_model(EXAMPLES / "triangle.toml")
    clean = activebonds.simulate(model, 61, 60.0)
    rng = np.random.default_rng(11)
    noisy = clean.positions + rng.normal(0, 5e-4, clean.positions.shape)
    traj = Trajectory(positions=noisy, markers=clean.markers, rate=clean.rate, mask=clean.mask)
    settings = FitSettings(horizon=(10,), cost="shooting", refine="lm", bonds="standard")
    ident = identification(model, traj, settings)
    start = ident.model.layout.initial() * 1.02
    refinements = {
        path: Refinement(ident, settings, solver=path) for path in ("dense", "structured")
    }
    stages = {path: r.stage(10, start) for path, r in refinements.items()}
    dense, structured = stages["dense"], stages["structured"]
    assert dense.accepted and structured.accepted
    a, b = np.asarray(dense.genome), np.asarray(structured.genome)
    report = estimate(ident, settings, a, 10, "shooting", refinements["dense"].states)
    se = np.array([e.std_error for e in report.estimates])
    layout = ident.model.layout
    assert np.max(np.abs(layout.natural(a) - layout.natural(b)) / se) < 0.05
    # d standard deviations from the optimum raise the loss by d^2 sigma^2 / 2 over a loss of
    # about dof sigma^2 / 2: at d = 0.05 and ~300 degrees of freedom, 1e-5 relative at most
    assert structured.end_rms_mm == pytest.approx(dense.end_rms_mm, rel=1e-5)


def test_the_curvature_of_a_step_is_its_dense_quadratic_form(problem):
    """d^T J^T J d from the blocks (the prediction of a step projected onto the bounds, which
    is not the damped solve's) is the dense matrix's, for an arbitrary step."""
    p, k, n = problem["p"], problem["k"], problem["n"]
    a = problem["jac"].T @ problem["jac"]
    rng = np.random.default_rng(5)
    du, ds = rng.normal(size=p), rng.normal(size=(k, n))
    got = float(curvature(problem["normal"], (jnp.asarray(du), jnp.asarray(ds))))
    d = np.concatenate([du, ds.ravel()])
    assert got == pytest.approx(float(d @ a @ d), rel=1e-9)
