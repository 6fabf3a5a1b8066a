"""The NRI springs generator (Kipf et al. 2018): graph statistics, dynamics, walls, dataset seeds."""

from __future__ import annotations

import tomllib

import numpy as np

from activebonds.experiments import springs


def _spring_acceleration(x: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """-k sum_j A_ij (x_i - x_j) at every frame, unit masses: [F, N, 2]."""
    return -springs.STRENGTH * (
        edges.sum(axis=1)[None, :, None] * x - np.einsum("ij,tjd->tid", edges, x)
    )


def test_edges_symmetric_zero_diagonal_about_half_set():
    rng = np.random.default_rng(0)
    fractions = []
    for _ in range(200):
        x, edges = springs.simulate(rng, n_frames=2)
        assert x.shape == (2, 5, 2)
        assert edges.shape == (5, 5) and edges.dtype.kind == "i"
        assert np.array_equal(edges, edges.T)
        assert not np.diag(edges).any()
        assert set(np.unique(edges)) <= {0, 1}
        fractions.append(edges[np.triu_indices(5, 1)].mean())
    # 2000 pairs at p = 1/2: standard error 0.011
    assert abs(np.mean(fractions) - 0.5) < 0.05


def test_second_difference_is_the_spring_force_away_from_walls():
    # 300 frames (30 s) so that this trajectory bounces off the walls
    x, edges = springs.simulate(np.random.default_rng(1), n_frames=299)
    assert np.all(np.abs(x) <= springs.BOX)
    wall = springs.near_wall(x)
    assert wall.shape == (299, 5) and wall.any()
    d2 = (x[2:] - 2 * x[1:-1] + x[:-2]) / springs.FRAME_DT**2
    acc = _spring_acceleration(x, edges)[1:-1]
    ok = ~(wall[2:] | wall[1:-1] | wall[:-2])
    assert ok.mean() > 0.8
    residual = d2[ok] - acc[ok]
    assert np.linalg.norm(residual) / np.linalg.norm(acc[ok]) < 1e-3
    # the flagged frames are needed: a bounce is no spring force
    assert np.abs(d2 - acc).max() > 1.0


def test_dataset_reproducible_and_noise_has_the_given_std():
    clean = springs.dataset(3, seed=7)
    again = springs.dataset(3, seed=7)
    noisy = springs.dataset(3, seed=7, noise=0.05)
    assert len(clean) == 3
    for (x, a), (y, b), (_, c) in zip(clean, again, noisy, strict=True):
        assert x.shape == (49, 5, 2)
        assert np.array_equal(x, y) and np.array_equal(a, b)
        assert np.array_equal(a, c)
        assert np.all(np.abs(x) <= springs.BOX)
    deviation = np.concatenate(
        [(z - x).ravel() for (x, _), (z, _) in zip(clean, noisy, strict=True)]
    )
    assert abs(deviation.std() / 0.05 - 1) < 0.1
    assert abs(deviation.mean()) < 0.01
    assert not np.array_equal(springs.dataset(3, seed=8)[0][0], clean[0][0])


def test_candidate_model_has_one_optional_spring_per_pair():
    model = tomllib.loads(springs.candidate_model_toml())
    assert model["name"] == "springs" and model["dimension"] == 2
    assert [p["name"] for p in model["particle"]] == [f"p{i}" for i in range(5)]
    assert all(p["mass"] == 1.0 for p in model["particle"])
    bonds = model["bond"]
    assert len(bonds) == 10
    assert len({b["type"] for b in bonds}) == 10
    assert bonds[0]["type"] == "k0_1" and bonds[0]["particles"] == ["p0", "p1"]
    for b in bonds:
        assert b["kind"] == "binary" and b["optional"] is True
        assert b["stiffness"] == {"value": 0.05, "min": 0.0, "max": 1.0}
        assert b["rest_length"] == 0.0 and b["damping"] == 0.0
