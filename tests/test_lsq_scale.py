"""The exact least squares at scale: the compressed solve (QR to K + 1 rows, the product
constraints as a least distance problem) gives the genome of an independent solve of the
uncompressed system, and structure identification on column subsets of one compressed
problem gives the costs of solving each structure's own model."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy.optimize import LinearConstraint, lsq_linear, minimize

from activebonds.identify.costs.windows import make_windows
from activebonds.identify.discover import structure as st
from activebonds.identify.solvers.lsq import (
    LinearProblem,
    compress,
    least_squares,
    linear_problem,
    solve,
)
from activebonds.model import load_model, loads_model
from activebonds.simulation import simulate
from helpers import ROOT

TETRA = ROOT / "tests" / "models" / "tetra.toml"


def random_problem(seed: int, rows=300, k=12, n_pairs=3, tight=False) -> LinearProblem:
    """Columns of very different scales, bounds, and ``n_pairs`` products (k, k x)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(rows, k)) * np.exp(rng.uniform(-4, 4, k))
    theta = rng.uniform(0.5, 2.0, k)
    lower, upper = np.full(k, 0.1), np.full(k, 3.0)
    pairs = []
    for i in range(n_pairs):
        kk, p = 2 * i, 2 * i + 1  # p = k x, x in [0.8, 1.2] (tight: the truth 1.5 outside)
        theta[p] = theta[kk] * (1.5 if tight else 1.0)
        lower[p], upper[p] = 0.1 * 0.8, 3.0 * 1.2
        pairs.append((kk, p, 0.8, 1.2))
    lower[-1] = theta[-1] + 0.2  # a bound that holds
    target = a @ theta + rng.normal(0, 1e-3, rows) * np.abs(a).mean()
    return LinearProblem(
        columns=a,
        offset=np.zeros(rows),
        target=target,
        names=tuple(f"gene:{i}" for i in range(k)),
        lower=lower,
        upper=upper,
        pairs=tuple(pairs),
        n_terms=rows,
    )


def reference(problem: LinearProblem) -> np.ndarray:
    """Independent of the compression: scipy's BVLS on the uncompressed scaled system (where
    that breaks a product constraint, SLSQP with every constraint, from it) finds the active
    set; the optimum on it is then the unconstrained least squares of the uncompressed
    columns with the held unknowns substituted (at a bound, or a product at k lo or k hi)."""
    a, rhs = problem.columns, problem.target - problem.offset
    norm = np.linalg.norm(a, axis=0)
    a_s = a / norm
    lo, hi = problem.lower * norm, problem.upper * norm
    z = lsq_linear(a_s, rhs, bounds=(lo, hi), method="bvls", tol=1e-15, lsmr_tol=None).x
    if any(
        not z[k] / norm[k] * xlo <= z[p] / norm[p] <= z[k] / norm[k] * xhi
        for k, p, xlo, xhi in problem.pairs
    ):
        rows = []
        for k, p, xlo, xhi in problem.pairs:
            r1, r2 = np.zeros(len(norm)), np.zeros(len(norm))
            r1[p], r1[k] = 1 / norm[p], -xlo / norm[k]
            r2[p], r2[k] = -1 / norm[p], xhi / norm[k]
            rows += [r1, r2]
        z = minimize(
            lambda z: 0.5 * np.sum((a_s @ z - rhs) ** 2),
            z,
            jac=lambda z: a_s.T @ (a_s @ z - rhs),
            method="SLSQP",
            bounds=list(zip(lo, hi, strict=True)),
            constraints=[LinearConstraint(np.array(rows), 0.0, np.inf)],
            options={"ftol": 1e-300, "maxiter": 5000},
        ).x
    t = z / norm
    n = len(t)
    span = problem.upper - problem.lower
    # theta = base + basis @ psi: held unknowns in base, a held product follows its k
    base, basis = np.zeros(n), np.eye(n)
    held = {}
    for i in range(n):
        for bound in (problem.lower[i], problem.upper[i]):
            if abs(t[i] - bound) <= 1e-6 * span[i]:
                held[i] = bound
    for k, p, xlo, xhi in problem.pairs:
        for x in (xlo, xhi):
            if abs(t[p] / t[k] - x) <= 1e-6 * (xhi - xlo):
                basis[:, p] = 0.0
                basis[p] = x * basis[k]
                base[p] = x * held.get(k, 0.0)
                held.pop(p, None)
    for i, bound in held.items():
        basis[:, i] = 0.0
        basis[i] = 0.0
        base[i] = bound
    keep = np.abs(basis).sum(axis=0) > 0
    m = a @ basis[:, keep]
    psi, *_ = np.linalg.lstsq(m, rhs - a @ base, rcond=None)
    return base + basis[:, keep] @ psi


def test_compress_keeps_every_cost():
    rng = np.random.default_rng(1)
    a, rhs = rng.normal(size=(500, 20)), rng.normal(size=500)
    r, c = compress(a, rhs)
    assert r.shape == (21, 20) and not np.tril(r[:20], -1).any()
    for _ in range(5):
        t = rng.normal(size=20)
        assert np.sum((r @ t - c) ** 2) == pytest.approx(np.sum((a @ t - rhs) ** 2), rel=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("tight", [False, True])
def test_the_solve_is_the_uncompressed_optimum_on_random_bounded_problems(seed, tight):
    problem = random_problem(seed, tight=tight)
    got, exact = solve(problem)
    want = reference(problem)
    assert exact
    np.testing.assert_allclose(got, want, rtol=1e-8)
    if tight:  # the product constraints are what holds the optimum
        assert any(
            abs(got[p] - got[k] * xhi) < 1e-9 * abs(got[p]) for k, p, _, xhi in problem.pairs
        )
    assert got[-1] == pytest.approx(problem.lower[-1], rel=1e-12)  # at its bound


@pytest.fixture(scope="module")
def springs():
    """The tetrahedron of springs simulated, and a version with tight rest-length bounds that
    exclude the truth of two bonds (their products k l0 held at k lo or k hi)."""
    jax.config.update("jax_enable_x64", True)
    model = load_model(TETRA)
    data = simulate(model, 120, 50.0)
    windows = make_windows(data.positions, data.mask, data.dt, 1)
    data = data.with_positions(
        data.positions + np.random.default_rng(3).normal(0, 1e-4, data.positions.shape)
    )
    noisy = make_windows(data.positions, data.mask, data.dt, 1)
    return model, windows, noisy


# two rest lengths' bounds that exclude their truth (0.6 and 0.45): k l0 held at k lo, k hi
TIGHT = {
    "rest_length = { value = 0.6, min = 0.3, max = 0.9 }": (
        "rest_length = { value = 0.65, min = 0.63, max = 0.9 }"
    ),
    "rest_length = { value = 0.45, min = 0.2, max = 0.7 }": (
        "rest_length = { value = 0.4, min = 0.2, max = 0.43 }"
    ),
}


@pytest.mark.parametrize("tight", [False, True])
def test_the_solve_is_the_uncompressed_optimum_on_a_spring_model(springs, tight):
    model, _, windows = springs
    if tight:
        text = TETRA.read_text()
        for old, new in TIGHT.items():
            assert old in text
            text = text.replace(old, new)
        model = loads_model(text)
    problem = linear_problem(model, windows)
    got, exact = solve(problem)
    want = reference(problem)
    assert exact
    np.testing.assert_allclose(got, want, rtol=1e-8)
    held = sum(
        min(abs(got[p] - got[k] * xlo), abs(got[p] - got[k] * xhi)) < 1e-9 * abs(got[p])
        for k, p, xlo, xhi in problem.pairs
    )
    assert held == (2 if tight else 0)


def candidates_toml(text: str) -> str:
    return text.replace('kind = "binary"', 'kind = "binary"\noptional = true')


def test_structure_on_column_subsets_is_each_structure_solved_on_its_own(springs):
    """Every bond of the tetrahedron a candidate: the compressed column subsets give the
    RSS and BIC of building and solving each structure's own model."""
    _, _, windows = springs
    text = TETRA.read_text()
    for old, new in TIGHT.items():
        text = text.replace(old, new)
    candidates = loads_model(candidates_toml(text))
    pool = st.candidates(candidates.spec)
    assert len(pool) == 6
    fast = st._Scorer(candidates, windows, pool)
    slow = st._Scorer(candidates, windows, pool)
    assert fast.subsets is not None
    slow.subsets = None
    rng = np.random.default_rng(0)
    for _ in range(8):
        present = frozenset(int(i) for i in pool if rng.uniform() < 0.6)
        rss, bic = fast(present)
        rss_own, bic_own = slow(present)
        assert rss == pytest.approx(rss_own, rel=1e-8)
        assert bic == pytest.approx(bic_own, rel=1e-10)


def test_a_fixed_term_or_a_shared_type_takes_the_per_structure_path(springs):
    _, _, windows = springs
    text = candidates_toml(TETRA.read_text())
    fixed = text.replace("damping = { value = 0.8, min = 0.01, max = 10.0 }", "damping = 0.8")
    shared = text.replace('particles = ["A", "B"]', 'type = "t"\nparticles = ["A", "B"]')
    shared = shared.replace('particles = ["B", "D"]', 'type = "t"\nparticles = ["B", "D"]')
    for variant in (fixed, shared):
        model = loads_model(variant)
        scorer = st._Scorer(model, windows, st.candidates(model.spec))
        assert scorer.subsets is None
        everything = frozenset(st.candidates(model.spec))
        assert scorer(everything)[0] == least_squares(model, windows).cost
