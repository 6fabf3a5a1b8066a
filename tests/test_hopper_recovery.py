"""Contacts under substeps and multiple shooting, on a hopper from an independent fine
integrator (tests/hopper_truth.py: semi-implicit Euler at 1e-5 s, 200 Hz; issue 24).

A sticking contact's friction is a drag of ``mu Fn / eps`` (eps = 1e-3 m/s): for the model's
substeps (0.25 ms at 20 per frame) an explicit kick is unstable there and the start
velocity's fixed point diverges (most sticking frames cost +inf). The substeps' kicks are
linearly implicit in the contact's velocity dependence and the start velocity is solved by
Newton's method (activebonds.physics.integrate)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hopper_truth
from activebonds.model import loads_model
from activebonds.physics import advance, start_velocity
from activebonds.physics.integrate import stiff


@pytest.fixture(scope="module")
def truth():
    return hopper_truth.hopper()


def test_the_generator_lands_slides_sticks_and_bounces(truth):
    contact, sticking = truth.in_contact(), truth.sticking()
    assert contact[:, 1].mean() > 0.5 and contact[:, 0].mean() > 0.1  # foot and body land
    assert sticking[:, 1].mean() > 0.3  # the foot sticks
    sliding = contact & ~truth.sticking(0.05)
    assert sliding[:, 1].sum() > 5  # ... and slides
    assert (truth.positions[:, 0, 2] > 0.15).sum() > 50  # the body bounces off the ground


def test_the_generators_float_loop_is_its_numpy_definition_to_the_bit(truth):
    """The generator runs on Python floats (hopper_truth.integrate); from the samples before
    the foot lands (then slides and sticks), the body lands, and both are on the ground, four
    frames of it are those of the NumPy definition (hopper_truth.forces), to the bit."""
    contact = truth.in_contact()
    starts = [np.argmax(contact[:, 1]) - 1, np.argmax(contact[:, 0]) - 1]
    starts.append(np.argmax(contact[:, 0] & contact[:, 1]) - 1)
    assert truth.sticking()[starts[0] : starts[0] + 4, 1].any()
    per_frame = int(round(1.0 / (truth.rate * truth.step)))
    for f in starts:
        x, v = truth.positions[f], truth.velocities[f]
        want = hopper_truth.integrate_numpy(x, v, 4, per_frame, truth.step)
        got = hopper_truth.integrate(x, v, 4, per_frame, truth.step)
        for a, b in zip(got, want, strict=True):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(got[0][1:], truth.positions[f + 1 : f + 4])


def test_substeps_integrate_a_sticking_contact_close_to_the_fine_integrator(truth):
    """From the true states, one frame at 20 Verlet substeps lands within 0.1 mm of the fine
    integrator in every frame (sticking included) and within 10 um in the median."""
    model = loads_model(truth.model_toml("truth"), "hopper")
    assert stiff(model.topology)
    step = jax.jit(
        jax.vmap(lambda x, v: advance(model.params, model.topology, x, v, 0.005, 20, "verlet")[0])
    )
    x = np.asarray(step(jnp.asarray(truth.positions[:-1]), jnp.asarray(truth.velocities[:-1])))
    err = np.linalg.norm(x - truth.positions[1:], axis=-1).max(axis=1)
    assert np.median(err) < 1e-5, np.median(err)
    assert err.max() < 1e-4, err.max()


def test_start_velocities_are_solved_through_sticking(truth):
    """Newton's method solves the start velocity of almost every frame (the fixed point
    failed in 231 of 236 sticking frames), close to the fine integrator's velocity."""
    model = loads_model(truth.model_toml("truth"), "hopper")
    dt = 1.0 / truth.rate
    solve = jax.jit(
        jax.vmap(
            lambda a, b: start_velocity(
                model.params, model.topology, a, b, dt, 20, "verlet", with_residual=True
            )
        )
    )
    v, r = solve(jnp.asarray(truth.positions[:-1]), jnp.asarray(truth.positions[1:]))
    v, r = np.asarray(v), np.asarray(r)
    assert np.isfinite(v).all()  # no frame costs +inf
    unsolved = r > 0
    assert unsolved.mean() < 0.06, unsolved.sum()
    assert r.max() < 1e-4  # m: where Newton's method stalls, it stalls close
    err = np.linalg.norm(v - truth.velocities[1:], axis=-1).max(axis=1)
    assert np.median(err[~unsolved]) < 1e-3, np.median(err[~unsolved])  # m/s


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing); 70 s quiet, 3 min under load
def test_the_recommended_fit_recovers_the_hopper_without_noise(truth):
    """The recommended command for real data (without --init lsq, which contact bonds do not
    enter): the search on the one-step cost, then multiple shooting, windows of 10 frames at
    20 Verlet substeps. Measured (scripts/hopper_recovery.py --noise-mm 0): foot mass +1.0 %,
    leg stiffness -1.3 %, rest length +0.03 %, leg damping +1.4 %, contact height +0.7 %,
    stiffness -1.4 %, damping -0.9 %, friction -2.7 %."""
    from activebonds import fit

    model = loads_model(truth.model_toml("start"), "hopper")
    result = fit(
        model,
        truth.trajectory(),
        seed=0,
        init="uniform",
        cost="shooting",
        horizon=(10,),
        substeps=20,
        integrator="verlet",
    )
    stage = result.refinement[-1]
    assert stage.accepted, stage.message
    nat = dict(
        zip(
            (g.name for g in model.layout.genes),
            model.layout.natural(np.asarray(result.genome)),
            strict=True,
        )
    )
    t = hopper_truth.TRUTH
    tolerance = {  # the Done-when, without noise
        ("mass:foot.mass", "foot_mass"): 0.05,
        ("type:leg.stiffness", "leg.stiffness"): 0.02,
        ("type:leg.rest_length", "leg.rest_length"): 0.02,
        ("type:leg.damping", "leg.damping"): 0.10,
        ("type:ground.height", "ground.height"): 0.02,
        ("type:ground.stiffness", "ground.stiffness"): 0.02,
        ("type:ground.damping", "ground.damping"): 0.10,
        ("type:ground.friction", "ground.friction"): 0.10,
    }
    errors = {key: abs(nat[gene] - t[key]) / t[key] for gene, key in tolerance}
    for (_, key), limit in tolerance.items():
        assert errors[key] < limit, errors
    # the starts the substeps could not solve are said, not silently +inf
    assert not any("cost +inf" in line for line in result.lines())
