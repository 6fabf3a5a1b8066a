"""``activebonds scaffold`` (a candidate model from a recording) and the fitted model's start
(``best_model.toml`` with positions and velocities; ``export --from TRAJ --frame N``)."""

from __future__ import annotations

import re
import tomllib

import numpy as np
import pytest

from activebonds.data import read_trajectory
from activebonds.data.orientation import guess_ground
from activebonds.data.trajectory import Trajectory
from activebonds.data.writers import write_trajectory
from activebonds.identify.discover.scaffold import scaffold
from activebonds.model import load_model, loads_model
from helpers import EXAMPLES, HORSE_TROT, cli_in_process

TRIANGLE_DATA = EXAMPLES / "triangle.csv"


def _recording(tmp_path, positions, mask=None, name="rec.csv", markers=None):
    positions = np.asarray(positions, float)
    if mask is None:
        mask = np.ones(positions.shape[:2], bool)
    positions = np.where(mask[..., None], positions, np.nan)
    markers = markers or tuple(f"M{i}" for i in range(positions.shape[1]))
    traj = Trajectory(positions=positions, mask=mask, markers=markers, rate=100.0)
    path = tmp_path / name
    write_trajectory(traj, path)
    return path


def _wobble(frames=60, particles=4, dimension=3, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.uniform(-0.3, 0.3, (particles, dimension))
    if dimension == 3:
        base[:, 2] += 0.5
    t = np.arange(frames)[:, None, None] / 100.0
    return base[None] + 0.01 * np.sin(2 * np.pi * 1.5 * t + rng.uniform(0, 6, (particles, 1)))


def _bad(tmp_path, data, *options):
    out = tmp_path / "model.toml"
    proc = cli_in_process("scaffold", data, "--out", out, *options)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert not out.exists() and not list(tmp_path.glob("*.toml"))
    return lines[0]


def test_one_marker_is_refused(tmp_path):
    data = _recording(tmp_path, _wobble(particles=3))
    line = _bad(tmp_path, data, "--markers", "M1")
    assert "one marker (M1)" in line and "--markers" in line


def test_no_complete_frame_is_refused(tmp_path):
    x = _wobble(particles=3)
    mask = np.ones(x.shape[:2], bool)
    mask[::2, 0] = False
    mask[1::2, 1] = False  # M0 and M1 are never seen together
    data = _recording(tmp_path, x, mask)
    line = _bad(tmp_path, data)
    assert "no frame of 0:60 holds every one of the 3 markers" in line


def test_a_flat_recording_asked_for_gravity_is_refused(tmp_path):
    planar = _recording(tmp_path, _wobble(dimension=2), name="planar.csv")
    line = _bad(tmp_path, planar, "--gravity")
    assert "a 2D recording" in line and "--up" in line
    x = _wobble()
    x[:, :, 2] = 0.25  # every marker at one height: flat along Z
    flat = _recording(tmp_path, x, name="flat.csv")
    line = _bad(tmp_path, flat, "--up", "Z")
    assert "flat along Z" in line
    line = _bad(tmp_path, flat, "--gravity")
    assert "a flat recording (no extent along Z)" in line


@pytest.mark.parametrize("mass", ["0", "-3"])
def test_a_total_mass_not_above_zero_is_refused(tmp_path, mass):
    data = _recording(tmp_path, _wobble())
    line = _bad(tmp_path, data, f"--total-mass={mass}")
    assert "--total-mass" in line and "> 0" in line


def test_unknown_markers_are_refused(tmp_path):
    data = _recording(tmp_path, _wobble())
    line = _bad(tmp_path, data, "--markers", "M0,Nope")
    assert "'Nope' not found" in line and "M0, M1, M2, M3" in line


def test_the_scaffold_of_the_trot_loads_and_says_where_every_number_comes_from(tmp_path):
    out = tmp_path / "trot.toml"
    proc = cli_in_process("scaffold", HORSE_TROT, "--out", out, "--total-mass", "500")
    assert proc.returncode == 0, proc.stderr
    text = out.read_text()
    model = load_model(out)  # loads as written
    spec = tomllib.loads(text)
    assert [p["name"] for p in spec["particle"]] == list(read_trajectory(HORSE_TROT).markers)
    # the vertical is +Z (clear ground guess), the four hooves touch the ground, on a belt
    assert spec["gravity"] == [0.0, 0.0, -9.81]
    contacts = [b for b in spec["bond"] if "normal" in b]
    assert sorted(b["particles"][0] for b in contacts) == ["HFL", "HFR", "HHL", "HHR"]
    belt = contacts[0]["surface_velocity"]
    assert belt[0] == pytest.approx(-2.89, abs=0.02) and belt[2] == 0.0
    springs = [b for b in spec["bond"] if "rest_length" in b]
    assert springs and all(b["optional"] is True for b in springs)
    assert sum(p["mass"] for p in spec["particle"]) == pytest.approx(500.0)
    for b in springs:
        r, k, c = b["rest_length"], b["stiffness"], b["damping"]
        assert r["min"] < r["value"] < r["max"]
        assert k["min"] < k["value"] < k["max"] and k["max"] / k["min"] > 1e4
        assert c["min"] < c["value"] < c["max"]
    # every line that sets a number carries a comment saying where it came from
    numeric = [line for line in text.splitlines() if re.match(r"^\w+ = [\[{\-0-9]", line)]
    numeric = [line for line in numeric if not line.startswith("particles")]
    assert len(numeric) > 50 and all("  # " in line for line in numeric), numeric
    # the placement: frame 0 of the recording
    np.testing.assert_allclose(
        model.initial_state()[0], read_trajectory(HORSE_TROT).positions[0], atol=1e-5
    )


def test_candidates_are_near_rigid_pairs_and_nearest_neighbours():
    rng = np.random.default_rng(1)
    base = np.array([[0, 0, 0], [0.1, 0, 0], [2, 0, 0], [2, 1, 0], [5, 5, 5.0]])
    x = base[None] + 0.02 * rng.standard_normal((80, 5, 3))
    x[:, 1] = x[:, 0] + [0.1, 0, 0]  # M0-M1 rigid
    x[:, 4] = x[:, 0] + [5, 5, 5]  # M0-M4 rigid, though far
    traj = Trajectory(x, np.ones((80, 5), bool), tuple(f"M{i}" for i in range(5)), 100.0)
    made = scaffold(traj, neighbours=2, gravity=False)
    spec = loads_model(made.text).spec
    pairs = {tuple(b.particles) for b in spec.bond}
    assert ("M0", "M4") in pairs and ("M0", "M1") in pairs  # near-rigid
    line = next(t for t in made.text.splitlines() if t.startswith("# M0-M4: "))
    assert "near-rigid (distance spread 0 % of its median)" in line
    assert ("M2", "M3") in pairs  # each other's nearest neighbour
    assert made.gravity == "none" and made.contacts == 0


def test_a_small_marker_set_gets_every_pair_and_an_anchor_per_marker():
    """Up to 8 markers: every pair (rest lengths free from 0 to twice the largest distance
    seen) and an anchor per marker (free 2 extents about its median), all optional; with
    --neighbours or beyond 8 markers, a neighbourhood graph and no anchor."""
    traj = read_trajectory(HORSE_TROT)
    made = scaffold(traj, frames=(0, 300), gravity=False)
    spec = loads_model(made.text).spec
    springs = [b for b in spec.bond if b.kind == "binary"]
    anchors = [b for b in spec.bond if b.kind == "unary"]
    assert len(springs) == 21 and len(anchors) == 7 and made.bonds == 28
    assert all(b.optional for b in spec.bond)
    x = np.asarray(traj.positions[:300])
    dist = np.linalg.norm(x[:, :, None] - x[:, None], axis=-1)
    extent = np.max(np.median(dist, axis=0))
    names = list(traj.markers)
    for b in springs:
        i, j = (names.index(n) for n in b.particles)
        assert b.rest_length.min == 0.0
        assert b.rest_length.max == pytest.approx(2 * dist[:, i, j].max(), rel=1e-5)
    for b in anchors:
        centre = np.median(x[:, names.index(b.particles[0])], axis=0)
        np.testing.assert_allclose(b.anchor.value, centre, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(b.anchor.min, centre - 2 * extent, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(b.anchor.max, centre + 2 * extent, rtol=1e-5, atol=1e-5)
        assert b.stiffness.min > 0 and b.stiffness.max / b.stiffness.min > 1e4
    assert "every pair (7 markers: the complete graph)" in made.text
    assert any("an anchor per marker" in n for n in made.notes)
    chosen = scaffold(traj, frames=(0, 300), gravity=False, neighbours=2)
    assert "unary" not in chosen.text and chosen.bonds < 21
    nine = _wobble(frames=80, particles=9)
    many = scaffold(
        Trajectory(nine, np.ones((80, 9), bool), tuple(f"M{i}" for i in range(9)), 100.0)
    )
    assert "unary" not in many.text and many.bonds < 36


def test_an_uncertain_vertical_gets_no_gravity_unless_named(tmp_path):
    x = _wobble(frames=80, particles=5)  # small wobbles about random points: no clear ground
    traj = Trajectory(x, np.ones(x.shape[:2], bool), tuple(f"M{i}" for i in range(5)), 100.0)
    made = scaffold(traj)
    assert made.gravity == "none" and any("uncertain" in n for n in made.notes)
    named = scaffold(traj, up="-Y")
    assert named.gravity == "+Y" and "gravity = [0.0, 9.81, 0.0]" in named.text


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_best_model_carries_its_start_and_exports_as_is(tmp_path):
    """A fit's best_model.toml holds the positions at the fitted window's first frame and the
    velocity from which the model's step lands on the next one: export and simulate take it
    without edits; export --from TRAJ --frame N starts any model elsewhere."""
    run = tmp_path / "run"
    proc = cli_in_process(
        "fit", EXAMPLES / "triangle.toml", TRIANGLE_DATA, "--out", run, "--frames", "5:40",
        "--population", "8", "--generations", "3", "--refine", "none",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    best = load_model(run / "best_model.toml")
    data = read_trajectory(TRIANGLE_DATA)
    x0, v0 = best.initial_state()
    np.testing.assert_allclose(x0, data.positions[5], atol=1e-12)
    xml = tmp_path / "best.xml"
    proc = cli_in_process("export", run / "best_model.toml", "--out", xml, "--rate", "60")
    assert proc.returncode == 0, proc.stderr
    sim = tmp_path / "sim.csv"
    proc = cli_in_process(
        "simulate", run / "best_model.toml", "--n-frames", "3", "--rate", "60", "--out", sim
    )
    assert proc.returncode == 0, proc.stderr
    # the model's first step lands on the recording's next frame (to the file's 0.001 mm)
    np.testing.assert_allclose(read_trajectory(sim).positions[1], data.positions[6], atol=2e-6)

    xml2 = tmp_path / "from.xml"
    proc = cli_in_process(
        "export", EXAMPLES / "triangle.toml", "--out", xml2, "--from", TRIANGLE_DATA,
        "--frame", "12",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    body = xml2.read_text()
    first = " ".join(repr(float(a)) for a in data.positions[12, 0])
    assert f'pos="{first}"' in body or all(repr(float(a)) in body for a in data.positions[12, 0])
    proc = cli_in_process(
        "export", EXAMPLES / "triangle.toml", "--out", tmp_path / "no.xml", "--from",
        TRIANGLE_DATA, "--frame", "99999",
    )  # fmt: skip
    assert proc.returncode == 2 and "--frame" in proc.stderr
    assert not (tmp_path / "no.xml").exists()


def test_neural_turns_the_present_springs_of_a_structure_result_into_neural_bonds(tmp_path):
    x = _wobble(particles=3)
    data = _recording(tmp_path, x)
    cand = tmp_path / "cand.toml"
    assert cli_in_process("scaffold", data, "--out", cand, "--no-gravity").returncode == 0
    spec = tomllib.loads(cand.read_text())
    first, *rest = cand.read_text().split("optional = true")
    absent, present = "optional = true\npresent = false", "optional = true\npresent = true"
    found = first + absent + present.join(rest)  # the first candidate absent, the others present
    found_path = tmp_path / "found.toml"
    found_path.write_text(found)
    out = tmp_path / "neural.toml"
    proc = cli_in_process("scaffold", data, "--neural", found_path, "--out", out)
    assert proc.returncode == 0, proc.stderr
    neural = load_model(out).spec
    assert len(neural.bond) == len(spec["bond"]) - 1
    assert not any(b.optional for b in neural.bond)
    springs = [b for b in neural.bond if getattr(b, "rest_length", None) is not None]
    anchors = [b for b in neural.bond if len(b.particles) == 1]  # a small scaffold's anchors
    assert springs and all(b.neural for b in springs)
    assert len(anchors) == 3 and len(springs) + 3 == len(neural.bond)


def test_the_default_masses_are_said_to_set_the_force_scale(tmp_path):
    data = _recording(tmp_path, _wobble())
    quiet = cli_in_process("scaffold", data, "--out", tmp_path / "a.toml", "--no-gravity")
    given = cli_in_process(
        "scaffold", data, "--out", tmp_path / "b.toml", "--no-gravity", "--total-mass", "2"
    )
    assert quiet.returncode == 0 and given.returncode == 0, quiet.stderr + given.stderr
    said = quiet.stdout + quiet.stderr
    assert "1 kg per marker (no --total-mass)" in said and "--total-mass KG" in said
    assert "no --total-mass" not in given.stdout + given.stderr


def test_the_next_command_keeps_the_frames_and_markers(tmp_path):
    data = _recording(tmp_path, _wobble())
    proc = cli_in_process(
        "scaffold",
        data,
        "--out",
        tmp_path / "a.toml",
        "--no-gravity",
        "--frames",
        "0:40",
        "--markers",
        "M0,M1,M2",
    )
    assert proc.returncode == 0, proc.stderr
    hint = (proc.stdout + proc.stderr).split("next: ")[1]
    assert "--frames 0:40" in hint and "--markers M0,M1,M2" in hint
    plain = cli_in_process("scaffold", data, "--out", tmp_path / "b.toml", "--no-gravity")
    assert "--frames" not in (plain.stdout + plain.stderr).split("next: ")[1]


def test_a_doubtful_ground_confirmed_by_the_flight_gets_gravity():
    """A body thrown onto a floor in MuJoCo (scripts/mujoco_thrown.py): the ground guess alone
    is doubtful (its flattest axis not clearly flatter), the acceleration in its 38 frames of
    flight (-9.6 m/s^2 along +Z) confirms it: gravity and the ground contacts are scaffolded."""
    import sys
    from pathlib import Path

    from activebonds.data.orientation import agree, guess_gravity, guess_ground

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
    import mujoco_thrown

    x = mujoco_thrown.simulate()
    traj = Trajectory(x, np.ones(x.shape[:2], bool), mujoco_thrown.NAMES, 100.0)
    ground, fall = guess_ground(traj), guess_gravity(traj)
    assert not ground.clear and agree(ground, fall) is True  # the flight decides
    made = scaffold(traj, total_mass=2.6)
    assert made.gravity == "-Z" and "gravity = [0.0, 0.0, -9.81]" in made.text
    assert any("confirmed by the acceleration in flight" in n for n in made.notes)
    assert made.text.count('kind = "contact"') == 5


HANGING = """
name = "hanging"
dimension = 3
gravity = [0.0, 0.0, -9.81]

[[particle]]
name = "M1"
mass = 0.4
position = [0.0, 0.0, 0.989]
velocity = [0.1, 0.1, 0.0]

[[particle]]
name = "M2"
mass = 0.3
position = [0.0, 0.0, 0.76]
velocity = [0.3, 0.4, 0.0]

[[particle]]
name = "M3"
mass = 0.2
position = [0.0, 0.0, 0.535]
velocity = [0.5, 0.8, 0.0]

[[bond]]
kind = "unary"
particles = ["M1"]
stiffness = 800.0
damping = 0.3
anchor = [0.0, 0.0, 1.0]

[[bond]]
kind = "binary"
particles = ["M1", "M2"]
stiffness = 600.0
rest_length = 0.22
damping = 0.3

[[bond]]
kind = "binary"
particles = ["M2", "M3"]
stiffness = 400.0
rest_length = 0.22
damping = 0.2
"""


def test_a_body_hanging_from_a_marker_is_not_stood_on_it_upside_down():
    """A chain hanging from a pivot that is not recorded, swinging gently (our simulator): its
    top marker is the flattest "ground" upside down, and no other cue disagrees. The vertical is
    then uncertain and no gravity is scaffolded; given --up, the bottom mass swinging through
    its lowest point gets no treadmill belt (its velocity there is no single one)."""
    from activebonds.data.orientation import guess_gravity, vertical_doubts
    from activebonds.model import loads_model
    from activebonds.simulation import simulate

    data = simulate(loads_model(HANGING), 300, 100.0)
    ground = guess_ground(data)
    assert (ground.axis, ground.up, ground.feet) == (2, -1.0, ("M1",))  # the cue upside down
    doubts = vertical_doubts(ground, guess_gravity(data))
    assert any("rests on M1 alone" in d and "hanging" in d for d in doubts)
    found = scaffold(data, total_mass=0.9)
    assert found.gravity == "none" and found.contacts == 0
    assert "gravity: none (the vertical is uncertain" in "\n".join(found.notes)
    told = scaffold(data, total_mass=0.9, up="Z")
    assert told.gravity == "-Z"
    model = tomllib.loads(told.text)
    contacts = [b for b in model["bond"] if b["kind"] == "contact"]
    assert contacts and all("surface_velocity" not in b for b in contacts)
    assert "treadmill" not in "\n".join(told.notes)


def test_a_body_at_rest_most_of_the_time_takes_its_vertical_from_its_flight():
    """Four markers dropped 0.18 m and then at rest (200 Hz, 46 frames falling of 400): every
    coordinate of the lowest marker is flat at rest, and along X it is flat throughout, so the
    ground cue names +X; the 35 flight frames accelerating at -9.81 m/s^2 along Z name the
    vertical, and the scaffold's gravity and contacts follow them."""
    rate, frames, falling = 200.0, 400, 46
    shape = np.array([[0, 0, 0.02], [0.3, 0.05, 0.02], [0.15, 0.2, 0.25], [0.1, -0.1, 0.4]])
    t = np.arange(frames) / rate
    height = np.where(np.arange(frames) < falling, 0.18 - 0.5 * 9.81 * t**2, 0.0)
    x = np.repeat(shape[None], frames, axis=0)
    x[:, :, 2] += np.maximum(height, 0.0)[:, None]
    markers = ("HeelL", "ToeL", "Hip", "Torso")
    data = Trajectory(positions=x, mask=np.ones((frames, 4), bool), markers=markers, rate=rate)
    assert guess_ground(data).up_text == "+X"  # the ground cue alone is wrong here
    found = scaffold(data, total_mass=4.0)
    assert found.gravity == "-Z"
    assert "the vertical from the acceleration in flight, up = +Z" in "\n".join(found.notes)
    model = tomllib.loads(found.text)
    assert model["gravity"] == [0.0, 0.0, -9.81]
    feet = {b["particles"][0] for b in model["bond"] if b["kind"] == "contact"}
    assert feet == {"HeelL", "ToeL"}


def _walker(scale: float, frames: int = 400, rate: float = 100.0) -> np.ndarray:
    """Two feet that alternate stance (on the ground, 0.1 mm of noise) and swing (up to 30 %
    of the hip's height), a hip, a back and a head, all at ``scale`` times a 0.8 m body,
    walking along X: positions [F, 5, 3]."""
    rng = np.random.default_rng(0)
    t = np.arange(frames) / rate
    x = np.zeros((frames, 5, 3))
    for i, shift in enumerate((0.0, np.pi)):
        lift = np.maximum(np.sin(2 * np.pi * t + shift), 0.0)
        x[:, i, 2] = 0.3 * 0.5 * scale * lift
        x[:, i, 1] = (i - 0.5) * 0.2 * scale
    for i, height in ((2, 0.5), (3, 0.6), (4, 0.8)):
        x[:, i, 2] = height * scale * (1.0 + 0.02 * np.sin(4 * np.pi * t))
    x[:, :, 0] = 0.5 * scale * t[:, None]
    return x + rng.normal(0.0, 1e-4 * scale, x.shape)


@pytest.mark.parametrize("scale", [1.0, 0.04])  # a 0.8 m body and a 3.2 cm one (a mouse's)
def test_ground_contacts_reach_scales_with_the_body(scale, monkeypatch):
    """A fixed 2 cm put a mouse's hip on the ground (a 3.2 cm body's hip is 1.6 cm above it);
    the reach scales with the body's size, so at both sizes only the two feet touch."""
    from activebonds.identify.discover.gravity import contact_blocks, contact_reach

    x = _walker(scale)
    mask = np.ones(x.shape[:2], bool)
    names = ["LF", "RF", "Hip", "Back", "Head"]
    notes: list[str] = []
    blocks = contact_blocks(x, mask, names, 2, 1.0, 0.04 * scale**3 * 1000, 0.01, notes)
    touching = re.findall(r'particles = \["(\w+)"\]', "\n".join(blocks))
    assert touching == ["LF", "RF"], notes
    reach = contact_reach(x)
    assert reach == pytest.approx(min(0.02, 0.07 * 0.8 * scale), rel=0.01)  # its length
    if scale < 0.1:  # the fixed 2 cm of before put the mouse's hip on the ground
        monkeypatch.setattr("activebonds.identify.discover.gravity.CONTACT_REACH_SHARE", 1.0)
        blocks = contact_blocks(x, mask, names, 2, 1.0, 0.04 * scale**3 * 1000, 0.01, [])
        fixed = re.findall(r'particles = \["(\w+)"\]', "\n".join(blocks))
        assert fixed[:3] == ["LF", "RF", "Hip"]
