"""Data from an independent simulator (MuJoCo's spatial tendons, RK4 at 1e-4 s): the
recommended refinement recovers the tendons; the one-step optimum cannot (issue 12)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

import activebonds  # noqa: E402
import mujoco_truth  # noqa: E402
from activebonds.model import loads_model  # noqa: E402


def relative_errors(model, genome, truth) -> dict[str, np.ndarray]:
    nat = dict(zip((g.name for g in model.layout.genes), model.layout.natural(genome), strict=True))
    out = {}
    for kind in ("stiffness", "rest_length", "damping"):
        out[kind] = np.array(
            [
                abs(nat[f"type:b{b.particles[0]}{b.particles[1]}.{kind}"] - getattr(b, kind))
                / getattr(b, kind)
                for b in truth.bonds
            ]
        )
    return out


def test_multiple_shooting_recovers_mujoco_tendons_within_1_percent():
    truth = mujoco_truth.tendon_system(n_particles=3, rate=100.0, seconds=1.0, seed=0)
    model = loads_model(truth.model_toml("start"), "mujoco")
    traj = truth.trajectory()
    base = dict(init="lsq", generations=1, population=8, seed=0)
    one_step = activebonds.fit(model, traj, **base)
    shot = activebonds.fit(
        model,
        traj,
        **base,
        refine="lm",
        cost="shooting",
        horizon=(10,),
        substeps=5,
        integrator="verlet",
    )
    assert shot.refinement[0].accepted
    errs = relative_errors(model, shot.genome, truth)
    for kind, e in errs.items():
        assert e.max() < 0.01, (kind, e)
    # the one-step optimum (one Euler step, backward-difference starts) is off by more
    base_errs = relative_errors(model, one_step.genome, truth)
    assert base_errs["damping"].max() > 3 * errs["damping"].max()
    assert base_errs["stiffness"].max() > 3 * errs["stiffness"].max()
