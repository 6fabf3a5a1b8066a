"""Gaps inside the fitted frames (issue 45, item 4): with a model's bond graph, a prediction
of particle p counts when p is present at s - 1, s and s + k and so is every particle within
k bonds of p at s - 1 and s; no frame needs every marker."""

from __future__ import annotations

from collections import deque

import jax
import numpy as np
import pytest

from activebonds.data.trajectory import Trajectory
from activebonds.identify.costs.windows import (
    count_predictions,
    make_cost,
    make_windows,
    neighbours_of,
)
from activebonds.identify.solvers.lsq import least_squares
from activebonds.model import loads_model
from activebonds.simulation import simulate

N = 6  # a chain P0 - P1 - ... - P5, P0 also anchored (a unary spring)
STIFFNESS = [40.0, 25.0, 60.0, 35.0, 50.0]
REST = [0.5, 0.45, 0.55, 0.4, 0.5]
DAMPING = [0.5, 0.8, 0.3, 0.6, 0.4]


def chain_text() -> str:
    rng = np.random.default_rng(7)
    parts = ['name = "chain"', "dimension = 3", ""]
    for i in range(N):
        x = [float(0.5 * i + 0.05 * rng.standard_normal()), float(0.1 * rng.standard_normal()), 0.0]
        v = [float(c) for c in 0.4 * rng.standard_normal(3)]
        parts += [
            "[[particle]]",
            f'name = "P{i}"',
            f"mass = {1.0 + 0.2 * i}",
            f"position = [{x[0]!r}, {x[1]!r}, {x[2]!r}]",
            f"velocity = [{v[0]!r}, {v[1]!r}, {v[2]!r}]",
            "",
        ]
    for i in range(N - 1):
        parts += [
            "[[bond]]",
            'kind = "binary"',
            f'particles = ["P{i}", "P{i + 1}"]',
            f"stiffness = {{ value = {STIFFNESS[i]}, min = 1.0, max = 1000.0 }}",
            f"rest_length = {{ value = {REST[i]}, min = 0.1, max = 1.0 }}",
            f"damping = {{ value = {DAMPING[i]}, min = 0.01, max = 10.0 }}",
            "",
        ]
    parts += [
        "[[bond]]",
        'kind = "unary"',
        'particles = ["P0"]',
        "stiffness = { value = 30.0, min = 1.0, max = 1000.0 }",
        "damping = { value = 0.2, min = 0.01, max = 10.0 }",
        "anchor = [0.0, 0.0, 0.0]",
        "",
    ]
    return "\n".join(parts)


@pytest.fixture(scope="module")
def chain():
    jax.config.update("jax_enable_x64", True)
    model = loads_model(chain_text())
    return model, simulate(model, 200, 50.0)


def rotating_gaps(n_frames: int, seed: int = 0) -> np.ndarray:
    """[F, N] presence with no frame complete: blocks of 5 frames, each with one particle
    missing in turn (P0, P1, ...), plus random single dropouts."""
    mask = np.ones((n_frames, N), bool)
    for f in range(n_frames):
        mask[f, (f // 5) % N] = False
    rng = np.random.default_rng(seed)
    mask[rng.random((n_frames, N)) < 0.03] = False
    return mask


def test_neighbours_of_a_chain(chain):
    model, _ = chain
    acting = neighbours_of(model)
    want = np.zeros((N, N), bool)
    for i in range(N - 1):
        want[i, i + 1] = want[i + 1, i] = True
    np.testing.assert_array_equal(acting, want)  # the anchor adds no neighbour


def test_least_squares_recovers_the_truth_without_a_complete_frame(chain):
    model, data = chain
    mask = rotating_gaps(data.n_frames)
    assert not mask.all(axis=1).any()  # no frame holds every marker
    positions = np.where(mask[..., None], data.positions, np.nan)
    gappy = Trajectory(positions, mask, data.markers, data.rate)
    old = make_windows(gappy.positions, gappy.mask, gappy.dt, 1)
    assert old.n_terms == 0  # the old rule keeps nothing
    windows = make_windows(gappy.positions, gappy.mask, gappy.dt, 1, 0, neighbours_of(model))
    assert np.all(np.isfinite(windows.x0)) and np.all(np.isfinite(windows.v0))
    # 44 % of the 198 starts x 6 particles (a particle's own and its neighbours' blocks
    # of missing frames remove the rest)
    assert windows.n_terms == brute_count(mask, 1, neighbours_of(model)) == 521
    result = least_squares(model, windows)
    assert result.exact
    truth = model.layout.natural(model.layout.initial())
    got = model.layout.natural(result.genome)
    np.testing.assert_allclose(got, truth, rtol=1e-9)
    assert result.rms_mm < 1e-9
    # the ES's cost on the same windows is finite and 0 at the truth (no NaN from the
    # filled start states of missing particles)
    cost, local = jax.jit(make_cost(model, windows))(model.layout.initial())
    assert np.all(np.isfinite(np.asarray(local)))
    assert float(cost) < 1e-24


def _hops(neighbours: np.ndarray) -> np.ndarray:
    """[P, P] bond distance by breadth-first search (a large number where unreachable)."""
    p = neighbours.shape[0]
    out = np.full((p, p), 10**6)
    for a in range(p):
        out[a, a] = 0
        queue = deque([a])
        while queue:
            u = queue.popleft()
            for w in np.flatnonzero(neighbours[u]):
                if out[a, w] > out[a, u] + 1:
                    out[a, w] = out[a, u] + 1
                    queue.append(w)
    return out


def brute_count(mask: np.ndarray, horizon: int, neighbours: np.ndarray | None) -> int:
    n_frames, p = mask.shape
    hops = None if neighbours is None else _hops(neighbours)
    kept = 0
    for s in range(1, n_frames - 1, horizon):
        for k in range(1, horizon + 1):
            if s + k >= n_frames:
                continue
            for q in range(p):
                if not mask[s + k, q]:
                    continue
                needed = range(p) if hops is None else np.flatnonzero(hops[q] <= k)
                if all(mask[s, r] and mask[s - 1, r] for r in needed):
                    kept += 1
    return kept


@pytest.mark.parametrize("horizon", [1, 2, 3])
def test_counts_equal_a_brute_force_count(horizon):
    rng = np.random.default_rng(horizon)
    p, f = 7, 60
    mask = rng.random((f, p)) > 0.12
    upper = np.triu(rng.random((p, p)) < 0.3, 1)
    neighbours = upper | upper.T
    kept, possible = count_predictions(mask, horizon, neighbours)
    assert kept == brute_count(mask, horizon, neighbours)
    assert count_predictions(mask, horizon)[0] == brute_count(mask, horizon, None)
    assert kept > count_predictions(mask, horizon)[0]  # the graph's rule keeps more
    positions = np.where(mask[..., None], rng.standard_normal((f, p, 3)), np.nan)
    assert make_windows(positions, mask, 0.01, horizon, 0, neighbours).n_terms == kept
    # every particle acting on every other: the old rule exactly
    full = ~np.eye(p, dtype=bool)
    assert count_predictions(mask, horizon, full) == count_predictions(mask, horizon)
    assert possible == count_predictions(mask, horizon)[1]


def test_a_missing_neighbour_stops_a_prediction_an_unrelated_one_does_not(chain):
    model, data = chain
    mask = np.ones((data.n_frames, N), bool)
    mask[10, 3] = False  # P3 missing at frame 10: the starts s = 10 and s = 11 read it
    positions = np.where(mask[..., None], data.positions, np.nan)
    w = make_windows(positions, mask, data.dt, 1, 0, neighbours_of(model))
    for s in (10, 11):
        row = w.weight[list(w.frames).index(s), 0]
        # P3 itself and its neighbours P2, P4 are not predicted; P0, P1, P5 are
        np.testing.assert_array_equal(row, [1, 1, 0, 0, 0, 1])
    assert w.weight[list(w.frames).index(12), 0].all()
    assert w.weight[list(w.frames).index(9), 0].tolist() == [1, 1, 1, 0, 1, 1]  # P3's target
    assert w.n_terms == 198 * N - 7
    # the old rule drops every particle there
    old = make_windows(positions, mask, data.dt, 1)
    assert old.n_terms == 198 * N - 2 * N - 1


def test_evaluate_scores_a_marker_where_it_and_its_neighbours_are_recorded(chain):
    """Judged frames where no frame holds every marker (seed 2 of
    scripts/gaitlab_recording.py left such a validation tail): `evaluate` counts a marker's
    prediction k frames ahead where it and the particles within k bonds of it are recorded
    at the start (the fit's rule), the model and zero force on the same terms: the truth
    predicts them exactly, zero force does not; the counts equal the brute force of the
    fit's windows. With every frame recorded, nothing changes."""
    from activebonds.identify.judge.predictions import zero_force_predictions
    from activebonds.report.evaluate import evaluate

    model, data = chain
    mask = rotating_gaps(data.n_frames)
    gappy = Trajectory(np.where(mask[..., None], data.positions, np.nan), mask, data.markers,
                       data.rate)  # fmt: skip
    found = evaluate(model, gappy, frames=(100, 160), horizon=3, origin=0)
    one, ahead = found.comparisons
    neighbours = neighbours_of(model)
    for c, k in ((one, 1), (ahead, 3)):
        assert c.terms == brute_ahead(mask[100:160], k, neighbours) > 0
        assert c.model_mm < 1e-6 < c.zero_force_mm
    assert len(one.worse_markers()) == 0
    whole = evaluate(model, data, frames=(100, 160), horizon=3, origin=0)
    assert [c.terms for c in whole.comparisons] == [58 * 6, 56 * 6]  # every start, marker
    rec = np.asarray(gappy.positions[100:160])
    _, run = zero_force_predictions(rec, rec.shape[0])  # no start: an empty free run
    assert np.isnan(run).all()


def brute_ahead(mask: np.ndarray, k: int, neighbours: np.ndarray) -> int:
    """Terms k frames ahead from every start s in 1..F-k-1: a marker whose target is
    recorded and whose particles within k bonds are recorded at s - 1 and s."""
    hops = _hops(neighbours)
    n_frames, p = mask.shape
    kept = 0
    for s in range(1, n_frames - k):
        for q in range(p):
            needed = np.flatnonzero(hops[q] <= k)
            if mask[s + k, q] and all(mask[s, r] and mask[s - 1, r] for r in needed):
                kept += 1
    return kept
