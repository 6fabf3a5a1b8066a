"""The variants of a scaffold's linear structure that ``activebonds auto`` chooses among on a
validation tail (identify/discover/structure_choice.py), and the one-step BIC that keeps or drops the
ground model."""

from __future__ import annotations

import numpy as np
import pytest

from activebonds.data import read_trajectory
from activebonds.identify.costs.windows import make_windows
from activebonds.identify.discover.scaffold import scaffold
from activebonds.identify.discover.structure_choice import (
    TIE,
    TRAIN,
    Variant,
    acceleration_masses,
    choose,
    criterion,
    linear_spec,
    momentum_masses,
    variants,
)
from activebonds.identify.solvers.lsq import least_squares
from activebonds.model import build, loads_model
from activebonds.simulation import simulate
from helpers import HORSE_TROT, TRIANGLE


def test_masses_in_inverse_proportion_to_the_rms_acceleration():
    t = np.arange(50)[:, None] * 0.01
    x = np.zeros((50, 3, 1))
    x[:, 0, 0] = np.sin(2 * np.pi * t[:, 0])  # amplitudes 1, 2 and 4 at one frequency
    x[:, 1, 0] = 2 * np.sin(2 * np.pi * t[:, 0])
    x[:, 2, 0] = 4 * np.sin(2 * np.pi * t[:, 0])
    m = acceleration_masses(x, 0.01, 7.0)
    np.testing.assert_allclose(m, [4.0, 2.0, 1.0], rtol=1e-12)
    still = np.zeros((10, 2, 3))  # no acceleration to measure: equal
    np.testing.assert_allclose(acceleration_masses(still, 0.01, 4.0), [2.0, 2.0])


def free_body(noise_mm: float, gravity: bool = False, seed: int = 0):
    """The triangle (three springs, masses 1, 1.5 and 2 kg) thrown free, 200 frames at
    60 Hz, with equal Gaussian noise on every coordinate; under gravity where asked."""
    from activebonds.data import Trajectory
    from activebonds.model import load_model

    model = load_model(TRIANGLE)
    if gravity:
        model = build(model.spec.model_copy(update={"gravity": [0.0, -9.81, 0.0]}))
    rec = simulate(model, 200, 60.0)
    rng = np.random.default_rng(seed)
    noisy = rec.positions + rng.normal(0.0, noise_mm / 1000.0, rec.positions.shape)
    return Trajectory(positions=noisy, mask=rec.mask, markers=rec.markers, rate=rec.rate)


@pytest.mark.parametrize("gravity", [False, True])
def test_masses_conserving_momentum_are_found_under_noise(gravity):
    truth = np.array([1.0, 1.5, 2.0])
    exact = momentum_masses(free_body(0.0, gravity).positions, 1 / 60, 4.5)
    np.testing.assert_allclose(exact, truth, rtol=1e-6)
    # half a millimetre of noise on motions of centimetres: the positions' parabolas, not
    # the accelerations, so the masses stay within a percent
    for seed in range(3):
        noisy = momentum_masses(free_body(0.5, gravity, seed).positions, 1 / 60, 4.5)
        np.testing.assert_allclose(noisy, truth, rtol=0.01)


def test_no_masses_conserve_momentum_where_an_outside_force_acts():
    t = np.arange(100)[:, None] / 60.0
    x = np.zeros((100, 2, 1))
    x[:, 0, 0] = np.sin(2 * np.pi * t[:, 0])  # in phase: no positive pair of masses keeps
    x[:, 1, 0] = 2 * np.sin(2 * np.pi * t[:, 0])  # their centre still
    assert momentum_masses(x, 1 / 60, 3.0) is None
    x[:, 1, 0] = -2 * x[:, 0, 0]  # in antiphase, twice as far: masses 2 and 1
    np.testing.assert_allclose(momentum_masses(x, 1 / 60, 3.0), [2.0, 1.0], rtol=1e-9)
    assert momentum_masses(x[:3], 1 / 60, 3.0) is None  # too few frames to tell


def test_a_variant_drops_gravity_and_contacts_and_sets_anchors_and_masses():
    traj = read_trajectory(HORSE_TROT)
    spec = loads_model(scaffold(traj, frames=(0, 300)).text).spec
    assert spec.gravity is not None and any(b.kind == "contact" for b in spec.bond)
    assert len(variants(spec)) == 12
    x = np.asarray(traj.positions[:300])
    for anchors in ("springs", "dampers", "none"):
        out = linear_spec(spec, Variant("acceleration", anchors, True), x, traj.dt)
        model = build(out)  # builds as written
        assert out.gravity is None and not any(b.kind == "contact" for b in out.bond)
        unary = [b for b in out.bond if b.kind == "unary"]
        assert len(unary) == {"springs": 7, "dampers": 7, "none": 0}[anchors]
        if anchors == "dampers":  # no stiffness and no anchor gene: a drag alone
            assert all(b.stiffness == 0.0 and isinstance(b.anchor, list) for b in unary)
            assert not any("anchor" in g.name for g in model.layout.genes)
        masses = [p.mass for p in out.particle]
        np.testing.assert_allclose(masses, acceleration_masses(x, traj.dt, 7.0), rtol=1e-12)
        assert sum(masses) == pytest.approx(7.0, rel=1e-12)
    same = linear_spec(spec, Variant(), x, traj.dt)
    assert [p.mass for p in same.particle] == [p.mass for p in spec.particle]


@pytest.fixture(scope="module")
def triangle_recording():
    """The triangle (three springs, masses 1, 1.5 and 2 kg, no anchor), 200 frames."""
    from activebonds.model import load_model

    return simulate(load_model(TRIANGLE), 200, 60.0)


def test_the_choice_is_the_best_tail_among_variants_better_at_every_marker(triangle_recording):
    rec = triangle_recording
    model = loads_model(scaffold(rec, frames=(0, 160), gravity=False).text)
    choice = choose(model, rec, (0, 160))
    split = int(round(TRAIN * 160))
    assert choice.train == (0, split) and choice.tail == (split, 160)
    assert len(choice.scored) == 18  # three kinds of masses (momentum's are positive here)
    better = [s for s in choice.scored if s.every_marker_better]
    assert better  # a spring model of a spring recording beats constant velocity
    lowest = min(s.tail_rms_mm for s in better)
    tied = [s for s in better if s.tail_rms_mm <= (1 + TIE) * lowest]
    best = min(tied, key=lambda s: (s.bonds, s.tail_rms_mm))
    assert choice.chosen == best.variant
    # the truth's masses are 1, 1.5 and 2 kg: those conserving momentum find them, and the
    # springs with them predict the tail to the integrator's own error
    assert best.variant.masses == "momentum"
    assert best.tail_rms_mm < 1e-3 * best.tail_zero_force_mm
    assert best.bonds == 3  # the three springs; no anchor survives the BIC
    guessed = [s for s in choice.scored if s.variant.masses != "momentum" and s.every_marker_better]
    assert min(s.tail_rms_mm for s in guessed) > 10 * best.tail_rms_mm
    record = choice.record()
    assert record["chosen"] == {"masses": best.variant.masses, "anchors": best.variant.anchors,
                                "decided": best.variant.decided}  # fmt: skip
    assert len(record["variants"]) == 18
    short = choose(model, rec, (0, 30))  # a 6-frame tail chooses nothing
    assert short is None


def test_the_criterion_is_the_one_step_bic_of_the_exact_cost(triangle_recording):
    rec = triangle_recording
    model = loads_model(scaffold(rec, frames=(0, 160), gravity=False).text)
    linear = build(linear_spec(model.spec, Variant(anchors="none"), rec.positions, rec.dt))
    data = rec.window(0, 160)
    fit = least_squares(linear, make_windows(data.positions, data.mask, data.dt, 1))
    solved = linear.with_genome(fit.genome)
    found = criterion(solved, rec, (0, 160))
    n = 158 * 3 * 3  # predicted frames x markers x coordinates
    assert found.n == n and found.k == linear.layout.n_genes == 9
    assert found.rss == pytest.approx(fit.cost, rel=1e-9)
    assert found.bic == pytest.approx(n * np.log(fit.cost / n) + 9 * np.log(n), rel=1e-12)
    assert found.rms_mm == pytest.approx(fit.rms_mm, rel=1e-9)


def _scored(masses, decided, tail, zero, per, per_zero, bonds):
    from activebonds.identify.discover.structure_choice import Scored, Variant

    return Scored(Variant(masses, "springs", decided), tail, zero, per, per_zero, bonds)


def test_a_tail_no_variant_predicts_better_than_zero_force_chooses_nothing():
    from activebonds.identify.discover.structure_choice import Variant, pick

    # a body at rest on the tail: zero force predicts it best; every variant is worse
    rest = [
        _scored("scaffold", True, 0.2100, 0.1333, (0.2, 0.2), (0.1, 0.1), 9),
        _scored("scaffold", False, 0.2038, 0.1333, (0.2, 0.2), (0.1, 0.1), 15),
        _scored("acceleration", False, 0.2050, 0.1333, (0.2, 0.2), (0.1, 0.1), 15),
    ]
    chosen, why = pick(rest)
    assert chosen == Variant()  # the BIC's decision, the scaffold's masses and anchors
    assert why.startswith("no variant predicts the tail better than zero force (the lowest")
    assert "0.2038 vs 0.1333 mm" in why
    # one variant better than zero force overall (not at every marker): the tail chooses
    moving = [
        *rest[:2],
        _scored("acceleration", False, 0.1300, 0.1333, (0.2, 0.05), (0.1, 0.1), 15),
    ]
    chosen, why = pick(moving)
    assert chosen == Variant("acceleration", "springs", False) and why == ""
    # better at every marker wins over a lower overall RMS; within TIE the fewest bonds
    every = _scored("momentum", True, 0.1310, 0.1333, (0.12, 0.12), (0.13, 0.13), 9)
    assert pick([*moving, every])[0] == Variant("momentum", "springs", True)
    tie = _scored("scaffold", True, 0.1310 * 1.0005, 0.1333, (0.12, 0.12), (0.13, 0.13), 8)
    assert pick([*moving, every, tie])[0] == Variant("scaffold", "springs", True)


THROWN = """
name = "thrown"
dimension = 3
gravity = [0.0, 0.0, -9.81]
{particles}{springs}{contacts}"""
# (a, b, stiffness N/m, damping N s/m, rest length m)
THROWN_SPRINGS = (
    ("a", "b", 400.0, 0.5, 0.25),
    ("b", "c", 250.0, 0.3, 0.2),
    ("a", "c", 300.0, 0.4, 0.3),
)


def _thrown_body():
    """Three unequal masses on springs, thrown up and sideways onto a ground with friction:
    0.57 s in flight, then bouncing (a second flight) and sliding (our own simulator, 10 Verlet substeps at
    100 Hz)."""
    start = {"a": (0.0, 0.0, 0.5), "b": (0.22, 0.05, 0.55), "c": (0.05, 0.25, 0.62)}
    masses = {"a": 0.4, "b": 1.1, "c": 0.7}
    velocity = {"a": (1.0, 0.2, 2.0), "b": (1.3, 0.0, 1.6), "c": (0.8, 0.4, 2.3)}
    particles = "".join(
        f'[[particle]]\nname = "{n}"\nmass = {masses[n]!r}\nposition = {list(start[n])!r}\n'
        f"velocity = {list(velocity[n])!r}\n"
        for n in start
    )
    contacts = "".join(
        f'[[bond]]\nkind = "contact"\nparticles = ["{n}"]\nnormal = [0.0, 0.0, 1.0]\n'
        "stiffness = 2e4\ndamping = 40.0\nfriction = 0.5\n"
        for n in start
    )
    springs = "".join(
        f'[[bond]]\nkind = "binary"\nparticles = ["{a}", "{b}"]\nstiffness = {k!r}\n'
        f"damping = {c!r}\nrest_length = {rest!r}\n"
        for a, b, k, c, rest in THROWN_SPRINGS
    )
    text = THROWN.format(particles=particles, springs=springs, contacts=contacts)
    model = loads_model(text, "thrown")
    traj = simulate(model, n_frames=150, rate=100.0, substeps=10, integrator="verlet")
    return model, traj, np.array([masses[n] for n in start])


def test_masses_conserving_momentum_from_the_frames_in_flight():
    from activebonds.identify.discover.structure_choice import flight_frames, momentum_masses

    model, traj, truth = _thrown_body()
    x = np.asarray(traj.positions)
    flight = flight_frames(model.spec, x)
    assert flight is not None and 30 <= flight.sum() < len(flight) - 30  # it lands
    landed = np.flatnonzero(x[:, :, 2].min(axis=1) < 0.01)[0]
    assert flight[: landed - 2].all() and not flight[landed : landed + 5].any()
    found = momentum_masses(x, traj.dt, truth.sum(), flight)
    assert np.allclose(found, truth, rtol=0.01), found
    # every frame at once: the ground's forces bend the centre of mass off any parabola
    every = momentum_masses(x, traj.dt, truth.sum())
    assert every is None or np.max(np.abs(every / truth - 1)) > 0.05
    # 0.5 mm of noise on the 97 frames of its flights (0.4 % measured): within 2 %
    rng = np.random.default_rng(3)
    noisy = x + rng.normal(0.0, 5e-4, x.shape)
    found = momentum_masses(noisy, traj.dt, truth.sum(), flight_frames(model.spec, noisy))
    assert found is not None and np.max(np.abs(found / truth - 1)) < 0.02, found
    # no contact: every frame, one parabola (as before)
    assert flight_frames(model.spec.model_copy(update={"bond": model.spec.bond[:3]}), x) is None
