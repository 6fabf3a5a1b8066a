"""The exact least squares block by block (identify/solvers/lsq_blocks.py): a problem whose
unknowns fall into groups sharing no row is solved per group to the optimum of one solve of
the whole, bounds and product constraints included; a problem that does not fall apart is
one block."""

from __future__ import annotations

import numpy as np

from activebonds.identify.solvers.lsq import LinearProblem, _solve_block, solve
from activebonds.identify.solvers.lsq_blocks import blocks


def _problem(seed: int, joined: bool = False) -> LinearProblem:
    """Three groups of unknowns (4, 3 and 5 columns) on rows of their own, rows no column
    touches between them, a zero column, bounds that bind and one product pair (k, k x) with
    x in [0.2, 0.4]; ``joined``: one row touches the first two groups."""
    rng = np.random.default_rng(seed)
    sizes, rows_each = (4, 3, 5), 30
    k = sum(sizes) + 1  # the last unknown's column is zero
    columns = np.zeros((len(sizes) * rows_each + 10, k))
    start = 0
    for g, size in enumerate(sizes):
        columns[g * rows_each : (g + 1) * rows_each, start : start + size] = rng.standard_normal(
            (rows_each, size)
        )
        start += size
    if joined:
        columns[-1, 0] = columns[-1, 5] = 1.0
    target = rng.standard_normal(columns.shape[0])
    lower, upper = np.full(k, -0.15), np.full(k, 0.15)
    lower[7], upper[7] = 0.5, 2.0  # k of the pair, in the third group
    lower[8], upper[8] = 0.0, 0.8  # its product k x
    return LinearProblem(
        columns=columns,
        offset=0.1 * rng.standard_normal(columns.shape[0]),
        target=target,
        names=tuple(f"gene:{i}" for i in range(k)),
        lower=lower,
        upper=upper,
        pairs=((7, 8, 0.2, 0.4),),
        n_terms=columns.shape[0] // 3,
    )


def _cost(problem: LinearProblem, theta: np.ndarray) -> float:
    r = problem.columns @ theta + problem.offset - problem.target
    return float(r @ r)


def test_a_problem_in_blocks_is_solved_per_block_to_the_whole_optimum():
    for seed in range(4):
        problem = _problem(seed)
        parts = blocks(problem.columns, problem.pairs)
        assert sorted(len(u) for _, u in parts) == [1, 3, 4, 5]  # the zero column alone
        assert sum(len(r) for r, _ in parts) == 90  # the 10 untouched rows in no block
        apart, exact = solve(problem)
        whole, _ = _solve_block(problem)
        assert exact
        at_bound = np.isclose(whole, problem.lower) | np.isclose(whole, problem.upper)
        assert at_bound[:-1].sum() >= 2  # bounds bind: a constrained problem
        np.testing.assert_allclose(apart[:-1], whole[:-1], atol=1e-10)
        assert _cost(problem, apart) <= _cost(problem, whole) * (1 + 1e-12)
        assert 0.2 * apart[7] - 1e-12 <= apart[8] <= 0.4 * apart[7] + 1e-12


def test_a_problem_joined_by_one_row_is_one_block_and_a_pair_joins_its_unknowns():
    problem = _problem(1, joined=True)
    parts = blocks(problem.columns, problem.pairs)
    assert sorted(len(u) for _, u in parts) == [1, 5, 7]  # groups one and two joined
    columns = np.zeros((6, 2))
    columns[:3, 0], columns[3:, 1] = 1.0, 2.0
    assert len(blocks(columns, ())) == 2
    assert len(blocks(columns, ((0, 1, 0.0, 1.0),))) == 1
