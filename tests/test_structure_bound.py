"""The structure search's branch and bound (``structure.best_removal``): the choices of
backward elimination solving every removal, from a lower bound of each removal's BIC and one
or two bounded solves a step. Judged on the bundled horses' scaffolds (28 candidates, stiffness
and rest-length bounds active at the optimum) and on a noisy simulated spring network."""

from __future__ import annotations

import numpy as np
import pytest

from activebonds.data.bundled import dataset
from activebonds.data.readers import read_trajectory
from activebonds.identify.costs.windows import make_windows
from activebonds.identify.discover import structure as S
from activebonds.identify.discover.scaffold import scaffold
from activebonds.identify.problem import select_data
from activebonds.identify.settings import FitSettings
from activebonds.model import loads_model


def _case(name: str, frames: tuple[int, int]):
    rec = read_trajectory(dataset(name).path)
    found = scaffold(rec, frames=frames, gravity=False, name=name)
    model = loads_model(found.text, name)
    data = select_data(model, rec, FitSettings(frames=frames))
    return model, make_windows(data.positions, data.mask, data.dt, 1)


def _every_removal_solved(monkeypatch):
    """Backward elimination as it was: every removal solved (no bound)."""
    monkeypatch.setattr(S._Subsets, "lower_bounds", lambda self, present, scorer: None)


@pytest.mark.parametrize("name", ["horse-trot", "horse-walk"])
def test_the_bound_makes_backward_eliminations_choices(name, monkeypatch):
    model, windows = _case(name, (0, 120))
    assert len(S.candidates(model.spec)) <= 40
    solves = []
    solve = S._Subsets.solve
    monkeypatch.setattr(S._Subsets, "solve", lambda self, p: solves.append(p) or solve(self, p))
    fast = S.identify_structure(model, windows)
    fast_solves = len(solves)
    with monkeypatch.context() as m:
        _every_removal_solved(m)
        slow = S.identify_structure(model, windows)
    assert fast_solves < 0.5 * (len(solves) - fast_solves)  # fewer than half the bounded solves
    assert fast.removed == slow.removed and len(fast.removed) > 3
    assert fast.bic == slow.bic
    assert [(d.bond, d.present) for d in fast.decisions] == [
        (d.bond, d.present) for d in slow.decisions
    ]
    np.testing.assert_array_equal(
        [d.delta_bic for d in fast.decisions], [d.delta_bic for d in slow.decisions]
    )


def test_every_bound_is_below_the_exact_bic_where_bounds_are_active():
    model, windows = _case("horse-trot", (0, 120))
    pool = S.candidates(model.spec)
    score = S._Scorer(model, windows, pool)
    present = frozenset(pool)
    for _ in range(4):  # the full structure and three steps of elimination
        bounds = score.subsets.lower_bounds(present, score)
        exact = {i: score(present - {i})[1] for i in present}
        gaps = np.array([exact[i] - bounds[i] for i in present])
        assert np.all(gaps >= -S._slack(min(exact.values())))
        assert np.any(gaps > 1.0)  # bounds active: some removals cost more than the bound
        present = present - {min(exact, key=exact.get)}
    # the bounds matter here: the unconstrained optimum of the full structure is infeasible
    full = score.subsets
    keep, theta = full.optima[frozenset(pool)]
    free = np.linalg.lstsq(full.r[:, keep], full.c, rcond=None)[0]
    assert not np.allclose(free, theta, rtol=1e-3, atol=1e-9)


@pytest.mark.parametrize("noise", [0.0, 0.003])
def test_simulated_springs_choose_as_every_removal_solved(noise, monkeypatch):
    """NRI springs (``experiments.springs``: 5 particles, every pair a candidate), noiseless
    and with observation noise."""
    from activebonds.experiments.springs import candidate_model_toml
    from activebonds.experiments.springs import dataset as springs

    x, _ = springs(1, seed=5, noise=noise)[0]
    windows = make_windows(x, np.ones(x.shape[:2], bool), 0.1, 1)
    model = loads_model(candidate_model_toml())
    fast = S.identify_structure(model, windows)
    with monkeypatch.context() as m:
        _every_removal_solved(m)
        slow = S.identify_structure(model, windows)
    assert fast.removed == slow.removed and fast.removed
    assert fast.bic == slow.bic
