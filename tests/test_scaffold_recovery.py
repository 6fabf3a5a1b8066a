"""Recovery: scaffold + structure + fit find a known network from its simulated recording.

The truth: 8 particles of 0.5 kg at the corners of a perturbed 0.5 m cube, bonded by the
edges of the Delaunay triangulation of the rest shape but the longest (21 springs, 60-240 N/m,
damping 0.1 N s/m), under gravity, every particle with a frictionless ground contact
(2000 N/m). Dropped from 25 cm with random velocities, it bounces and rings. Simulated at
1000 Hz, kept at 100 Hz (every 10th frame), 600 frames, with 0.5 mm Gaussian marker noise.
The recipe as a user runs it: ``scaffold --up Z --total-mass 4``, ``structure``, ``fit
--init model --cost shooting --horizon 20`` (the estimator noise does not bias).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from activebonds.data.trajectory import Trajectory
from activebonds.data.writers import write_trajectory
from activebonds.model import load_model, loads_model
from activebonds.simulation import simulate
from helpers import cli_in_process

RATE, FRAMES, FINE, NOISE, MASS = 100.0, 600, 10, 0.5e-3, 0.5


def _truth():
    """(model text, {pair: stiffness}) of the known network."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(7)
    cube = np.array(list(itertools.product([0, 1], repeat=3)), float) * 0.5
    rest = cube + rng.uniform(-0.05, 0.05, cube.shape)
    edges = set()
    for simplex in Delaunay(rest).simplices:
        for a, b in itertools.combinations(sorted(int(i) for i in simplex), 2):
            edges.add((a, b))
    edges = sorted(edges, key=lambda e: -np.linalg.norm(rest[e[0]] - rest[e[1]]))[1:]
    stiffness = rng.uniform(60, 240, len(edges))
    names = [f"P{i}" for i in range(8)]
    start = rest + [0.0, 0.0, 0.25]
    velocity = rng.normal(0, 0.4, (8, 3)) + [0.3, 0.1, 0.0]
    lines = ['name = "truth"', "dimension = 3", "gravity = [0.0, 0.0, -9.81]"]
    for i, n in enumerate(names):
        lines += [
            "[[particle]]",
            f'name = "{n}"',
            f"mass = {MASS}",
            f"position = {start[i].tolist()}",
            f"velocity = {velocity[i].tolist()}",
        ]
    truth = {}
    for (i, j), k in zip(edges, stiffness, strict=True):
        lines += [
            "[[bond]]",
            'kind = "binary"',
            f'particles = ["{names[i]}", "{names[j]}"]',
            f"stiffness = {k}",
            f"rest_length = {np.linalg.norm(rest[i] - rest[j])}",
            "damping = 0.1",
        ]
        truth[(names[i], names[j])] = float(k)
    for n in names:
        lines += [
            "[[bond]]",
            'kind = "contact"',
            f'particles = ["{n}"]',
            "normal = [0.0, 0.0, 1.0]",
            "height = 0.0",
            "stiffness = 2000.0",
        ]
    return "\n".join(lines) + "\n", truth, rng


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_scaffold_structure_fit_recover_a_known_network(tmp_path):
    text, truth, rng = _truth()
    fine = simulate(loads_model(text), FRAMES * FINE, RATE * FINE)
    x = np.asarray(fine.positions)[::FINE]
    assert x[:, :, 2].min() < 0.0  # the contacts act
    x = x + rng.normal(0.0, NOISE, x.shape)
    names = tuple(f"P{i}" for i in range(8))
    data = tmp_path / "network.npz"
    write_trajectory(Trajectory(x, np.ones(x.shape[:2], bool), names, RATE), data)

    cand, found, run = tmp_path / "cand.toml", tmp_path / "found.toml", tmp_path / "run"
    proc = cli_in_process("scaffold", data, "--up", "Z", "--total-mass", "4", "--out", cand)
    assert proc.returncode == 0, proc.stderr
    assert "ground contacts" in proc.stdout
    proc = cli_in_process("structure", cand, data, "--out", found)
    assert proc.returncode == 0, proc.stderr
    proc = cli_in_process(
        "fit", found, data, "--out", run, "--init", "model", "--population", "40",
        "--generations", "100", "--cost", "shooting", "--horizon", "20",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr

    model = load_model(run / "best_model.toml")
    springs = {
        tuple(b.particles): b
        for b in model.spec.bond
        if getattr(b, "rest_length", None) is not None
    }  # the candidate springs
    decided = set(springs) | set(truth)
    right = sum((p in truth) == (p in springs and not springs[p].absent) for p in decided)
    assert right / len(decided) >= 0.95, (right, len(decided))
    errors = {
        p: springs[p].stiffness.value / k - 1
        for p, k in truth.items()
        if p in springs and not springs[p].absent
    }
    worst = max(abs(e) for e in errors.values())
    assert len(errors) == len(truth) and worst <= 0.05, errors
