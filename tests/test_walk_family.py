"""The walk family (identify/discover/walk/) and auto's walk candidate: the stride found from
fewer than two strides at any rate, a walk told from a body stepping in place, swinging or
wandering by its data alone (no name is read: the markers are called m0, m1, ...), and a walk
model's coefficients recovered from its own simulation."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from activebonds.data import Trajectory
from activebonds.identify.discover.walk import (
    Stride,
    Walk,
    WalkVariant,
    find_floor,
    find_stride,
    recognise,
    walk_spec,
)
from helpers import assert_periodic_coefficients


def _walker(rate=100.0, period_s=1.1, strides=1.7, speed=1.2, treadmill=False, lift=0.12,
            seed=0):  # fmt: skip
    """A legged body: a pelvis (3 markers bobbing twice a stride, swaying once), a head, and two feet (heel
    and toe each) half a stride apart, each on the floor (height 0.03-0.045 m, still on it)
    60 % of the stride and swung forward ``lift`` m high the rest; the body travels at
    ``speed`` m/s along x, or stays while the floor moves back (``treadmill``). Noise 0.1 mm.
    Markers named m0, m1, ... (Z up)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(strides * period_s * rate)) / rate
    stance = 0.6
    reach = speed * stance * period_s / 2  # the foot's reach ahead of the body at heel strike
    body = speed * t
    x = []
    for lag in (0.0, 0.5):
        s = (t / period_s + lag) % 1.0
        on = s < stance
        ramp = np.where(on, 0.0, (s - stance) / (1 - stance))
        offset = np.where(on, reach - 2 * reach * s / stance, -reach + 2 * reach * (0.5 - 0.5 *
                          np.cos(np.pi * ramp)))  # fmt: skip
        height = lift * np.sin(np.pi * ramp) ** 2
        side = 0.1 if lag else -0.1
        for dx, dz in ((-0.05, 0.045), (0.15, 0.03)):  # heel, toe
            x.append(np.stack([body + offset + dx, np.full_like(t, side), dz + height], 1))
    w = 2 * np.pi * t / period_s
    for dy in (-0.12, 0.0, 0.12):
        x.append(np.stack([body, dy + 0.03 * np.sin(w), 1.0 + 0.02 * np.cos(2 * w)], 1))
    x.append(np.stack([body + 0.05, 0.03 * np.sin(w), 1.7 + 0.02 * np.cos(2 * w)], 1))
    x = np.stack(x, 1)
    if treadmill:
        x[..., 0] -= body[:, None]
    return x + 1e-4 * rng.standard_normal(x.shape), rate, period_s


def _names(x):
    return [f"m{i}" for i in range(x.shape[1])]


@pytest.mark.parametrize("rate", [100.0, 240.0])
def test_the_stride_is_found_from_less_than_two_strides_at_any_rate(rate):
    x, rate, period_s = _walker(rate=rate, strides=1.6)
    stride = find_stride(x, rate)
    assert stride is not None and stride.trusted
    assert stride.period == pytest.approx(period_s * rate, rel=0.01)
    assert stride.frequency == pytest.approx(1 / period_s, rel=0.01)
    assert find_stride(x[: int(0.9 * period_s * rate)], rate) is None  # less than a stride


@pytest.mark.parametrize("treadmill", [False, True])
def test_a_walk_overground_or_on_a_treadmill_is_a_walk(treadmill):
    x, rate, period_s = _walker(treadmill=treadmill)
    found = recognise(x, rate, _names(x))
    assert isinstance(found, Walk), found
    assert set(found.floor.feet) == {0, 1, 2, 3}
    assert found.floor.axis == 2 and found.floor.up == 1.0
    assert found.floor.over[0] == pytest.approx(1.2, rel=0.05)
    surface = found.floor.surface[0]
    assert surface == pytest.approx(-1.2, rel=0.05) if treadmill else abs(surface) < 0.05
    assert all(isinstance(line, str) for line in found.lines(_names(x)))


def test_stepping_in_place_swinging_or_wandering_is_no_walk():
    x, rate, _ = _walker(speed=0.0)  # the feet lift and land where they were: no travel
    assert "does not travel" in recognise(x, rate, _names(x))
    t = np.arange(300) / 100.0  # a pendulum of three markers: it swings, it walks nowhere
    angle = 0.4 * np.sin(2 * np.pi * t / 1.3)
    swing = np.stack([np.stack([r * np.sin(angle), 0 * t, 2.0 - r * np.cos(angle)], 1)
                      for r in (0.5, 1.0, 1.5)], 1)  # fmt: skip
    assert isinstance(recognise(swing, 100.0, _names(swing)), str)
    rng = np.random.default_rng(1)  # markers wandering at random: no stride repeats
    wander = np.cumsum(rng.standard_normal((300, 6, 3)), axis=0) * 1e-3 + [0, 0, 1]
    assert "no stride" in recognise(wander, 100.0, _names(wander))


@pytest.mark.parametrize("drift", [0.8, -2.0])
def test_a_body_whose_feet_slide_over_the_floor_is_no_walk(drift):
    """The treadmill walk carried along at ``drift`` m/s (the whole recording, belt and
    body): the feet's surface moves and so does the body in the room, as a body sliding or
    tumbling over a floor (a thrown box) does; the same walk without the drift is one."""
    x, rate, _ = _walker(treadmill=True)
    t = np.arange(x.shape[0]) / rate
    assert isinstance(recognise(x, rate, _names(x)), Walk)
    slid = x.copy()
    slid[..., 0] += drift * t[:, None]
    found = recognise(slid, rate, _names(x))
    assert "do not stand" in found, found


def test_the_floor_is_found_through_gaps():
    x, rate, _ = _walker(rate=150.0)
    gappy = x.copy()
    gappy[40:60, 1] = np.nan
    gappy[100:130, 5] = np.nan
    floor = find_floor(gappy, rate, _names(x))
    assert floor is not None and set(floor.feet) == {0, 1, 2, 3}
    assert isinstance(recognise(gappy, rate, _names(x)), Walk)


def test_a_walk_model_is_recovered_from_its_own_simulation():
    """Truth: a walk model (3 harmonics, a segment spring pair) with random coefficients,
    simulated at 117 Hz (semi-implicit Euler, one substep: the one-step cost's own
    integration); the same model solved on the simulation recovers every coefficient, the
    spring's stiffness and damping."""
    from activebonds.identify.discover.gait import solve
    from activebonds.model import build
    from activebonds.simulation import simulate

    rate = 117.0
    x, _, period_s = _walker(rate=rate)
    names = _names(x)
    stride = Stride(period_s * rate, 0.0, rate, x.shape[0])
    spec = walk_spec(x, names, stride, WalkVariant(harmonics=3, segments=1e-3))
    springs = [b for b in spec.bond if b.kind == "binary"]
    assert springs  # the pelvis' markers and the feet's heel-toe pairs are rigid
    rng = np.random.default_rng(5)
    bonds = []
    for b in spec.bond:
        if b.kind == "binary":
            update = {
                "stiffness": b.stiffness.model_copy(update={"value": float(rng.uniform(50, 90))}),
                "damping": b.damping.model_copy(update={"value": float(rng.uniform(1, 3))}),
            }
        else:
            update = {}
            for h in range(1, 4):
                for wave in ("cos", "sin"):
                    p = getattr(b, f"{wave}{h}")
                    value = [float(v) for v in rng.uniform(-2, 2, 3) / h]
                    update[f"{wave}{h}"] = p.model_copy(update={"value": value})
        bonds.append(b.model_copy(update=update))
    particles = [
        p.model_copy(update={"position": [float(v) for v in x[0, i]], "velocity": [1.2, 0, 0]})
        for i, p in enumerate(spec.particle)
    ]
    truth = spec.model_copy(update={"bond": bonds, "particle": particles})
    recording = simulate(build(truth), 600, rate)
    positions = np.asarray(recording.positions)
    assert np.isfinite(positions).all()
    data = Trajectory(positions, np.ones(positions.shape[:2], bool), tuple(names), rate)
    solved = solve(spec, data, (0, 600))
    for got, want in zip(solved.spec.bond, truth.bond, strict=True):
        if want.kind == "binary":
            assert got.stiffness.value == pytest.approx(want.stiffness.value, rel=1e-4)
            assert got.damping.value == pytest.approx(want.damping.value, rel=1e-4)
        else:
            assert_periodic_coefficients(got, want)


def _workspace(tmp_path, x, rate, fitted):
    from activebonds.identify.settings import FitSettings

    said: list[str] = []
    names = tuple(_names(x))
    recording = Trajectory(x, np.isfinite(x).all(axis=-1), names, rate)
    return SimpleNamespace(
        structural=recording,
        options=SimpleNamespace(markers=None, up=None, total_mass=None),
        split=SimpleNamespace(fitted=fitted),
        folder=SimpleNamespace(path=tmp_path),
        noise=SimpleNamespace(window=0),
        say=said.append,
        note=lambda step, key, value: said.append(f"{step}.{key}"),
        one_step=lambda: FitSettings(frames=fitted, cost="restart", horizon=(1,)),
        said=said,
    )


def test_the_walk_candidate_is_proposed_where_the_body_walks_and_not_in_place(tmp_path):
    from activebonds.auto.candidates import CANDIDATES
    from activebonds.model import load_model

    candidate = next(c for c in CANDIDATES.entries() if c.name == "walk")
    x, rate, _ = _walker(rate=90.0, strides=2.0)
    ws = _workspace(tmp_path, x, rate, (0, int(0.8 * x.shape[0])))
    proposal = candidate.propose(ws, None)
    assert proposal is not None and proposal.run == "run-walk"
    model = load_model(proposal.model)
    assert model.spec.drive.frequency == pytest.approx(1 / 1.1, rel=0.02)
    assert {b.kind for b in model.spec.bond} == {"periodic"}  # nothing holds it to the room
    still, rate, _ = _walker(rate=90.0, strides=2.0, speed=0.0)
    ws = _workspace(tmp_path, still, rate, (0, int(0.8 * still.shape[0])))
    assert candidate.propose(ws, None) is None
    assert any("walk: not proposed" in line for line in ws.said)


def test_groups_no_force_joins_are_solved_apart_to_the_whole_models_optimum():
    """The walk's markers fall into groups (the pelvis' three joined by segment springs, each
    foot's heel and toe, every other marker alone); the solve group by group reaches the
    optimum of one solve of the whole model, coefficient for coefficient, on a noisy walk."""
    from activebonds.identify.discover.gait import family
    from activebonds.model import build

    rate = 100.0
    x, _, period_s = _walker(rate=rate, seed=3)
    names = _names(x)
    stride = Stride(period_s * rate, 0.0, rate, x.shape[0])
    spec = walk_spec(x, names, stride, WalkVariant(harmonics=3, segments=1e-3))
    parts = family.groups(spec)
    sizes = sorted(len(p) for p, _ in parts)
    assert 1 < len(parts) < len(names) and sizes[-1] >= 2
    assert sorted(k for p, _ in parts for k in p) == list(range(len(names)))
    assert sorted(i for _, b in parts for i in b) == list(range(len(spec.bond)))
    data = Trajectory(x, np.ones(x.shape[:2], bool), tuple(names), rate)
    apart = family.solve(spec, data, (0, x.shape[0]))
    whole = build(family._solved(spec, data, (0, x.shape[0])))
    got, want = _numbers(apart.spec.bond), _numbers(whole.spec.bond)
    assert len(got) == len(want) and np.abs(want).max() > 0.1  # a problem with an answer
    np.testing.assert_allclose(got, want, rtol=1e-7, atol=1e-9)
    from activebonds.model.schema import GravityParam

    free_gravity = GravityParam(value=9.8, min=5.0, max=12.0)  # one magnitude joins them all
    assert len(family.groups(spec.model_copy(update={"gravity": free_gravity}))) == 1


def _numbers(bonds) -> np.ndarray:
    """Every number of the bonds' values, in order."""
    out: list[float] = []

    def walk(v):
        if isinstance(v, dict):
            for key in sorted(v):
                walk(v[key])
        elif isinstance(v, list):
            for item in v:
                walk(item)
        elif isinstance(v, float):
            out.append(v)

    walk([b.model_dump() for b in bonds])
    return np.array(out)


def test_a_marker_seen_over_part_of_the_stride_gets_fewer_harmonics():
    """Harmonics by the largest phase gap: a marker hidden over 40 % of the stride gets one
    (its half cycle no longer than the gap), one hidden over 60 % none, one hidden a few
    frames keeps them all; the gap measured where the one-step prediction counts."""
    from activebonds.identify.discover.walk import harmonics_seen, phase_gaps

    rate, period_s = 100.0, 1.0
    x, _, _ = _walker(rate=rate, period_s=period_s, strides=1.8)
    stride = Stride(period_s * rate, 0.0, rate, x.shape[0])
    gappy = x.copy()
    frames = np.arange(x.shape[0])
    phase = (frames / (period_s * rate)) % 1.0
    gappy[(phase > 0.3) & (phase < 0.7), 4] = np.nan  # 40 % of every stride hidden
    gappy[(phase > 0.2) & (phase < 0.8), 5] = np.nan  # 60 %
    gappy[50:53, 6] = np.nan  # a short dropout
    gaps = phase_gaps(gappy, stride)
    assert gaps[4] == pytest.approx(0.43, abs=0.015)  # the prediction needs both neighbours
    assert gaps[5] == pytest.approx(0.63, abs=0.015) and gaps[0] == pytest.approx(0.01)
    seen = harmonics_seen(gappy, stride, 8)
    assert seen[4] == 1 and seen[5] == 0 and seen[6] == 8 and seen[0] == 8
    spec = walk_spec(gappy, _names(x), stride, WalkVariant(harmonics=8))
    forced = {b.particles[0]: b for b in spec.bond}
    assert "m5" not in forced and hasattr(forced["m4"], "cos1")
    assert not hasattr(forced["m4"], "cos2") or forced["m4"].cos2 is None
    from activebonds.identify.discover.gait import solve

    data = Trajectory(gappy, np.isfinite(gappy).all(axis=-1), tuple(_names(x)), rate)
    solved = solve(spec, data, (0, x.shape[0]))  # m5 alone, no force: nothing to solve there
    assert len(solved.spec.bond) == len(spec.bond) and len(solved.spec.particle) == len(_names(x))
