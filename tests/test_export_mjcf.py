"""``activebonds export --format mjcf``: the exported MuJoCo model moves as the model does.

Passive models (binary spring-dampers, unary anchors with dampers, gravity, 2D and 3D) are
exported, loaded in MuJoCo and stepped over 100 frames at 100 Hz; their positions are
compared with ``simulate``'s free runs twice: MuJoCo's semi-implicit Euler at the exported
timestep against ``simulate``'s Euler with as many substeps (the same integrator and step:
the same numbers up to rounding), and MuJoCo's RK4 at a 0.1 ms step against ``simulate``'s
velocity Verlet with 10 substeps (two other integrators near the continuous motion: the
forces agree; measured within 0.06 mm, asserted within 1 mm). Kinds MuJoCo cannot express
are refused in one line naming them, and nothing is written.
"""

from __future__ import annotations

import tomllib

import mujoco
import numpy as np
import pytest

from activebonds.errors import InputError
from activebonds.export import to_mjcf, write_mjcf
from activebonds.model import load_model, loads_model, parse_model
from activebonds.simulation import simulate
from helpers import EXAMPLES, TRIANGLE, cli

RATE = 100.0
FRAMES = 100
SUBSTEPS = 2  # the exported step: 5 ms
FINE = 10  # simulate's Verlet substeps against MuJoCo's RK4 (0.06 mm apart at most here)
RK4_STEP = 1e-4  # s

# A 3D chain hanging from two anchors on its first particle (their springs and dampers add up
# on one particle's joints) and one on its last, under gravity.
CHAIN3D = """
name = "chain3d"
dimension = 3
gravity = [0.0, 0.0, -9.81]

[[particle]]
name = "p0"
mass = 0.5
position = [0.0, 0.0, 0.0]
velocity = [0.1, 0.0, 0.0]

[[particle]]
name = "p1"
mass = { value = 0.7, min = 0.1, max = 2.0 }
position = [0.3, 0.0, 0.05]

[[particle]]
name = "p2"
mass = 0.4
position = [0.6, 0.1, 0.0]
velocity = [0.0, -0.2, 0.3]

[[bond]]
kind = "unary"
particles = ["p0"]
stiffness = 200.0
damping = 0.5
anchor = [0.0, 0.0, 0.05]

[[bond]]
kind = "unary"
particles = ["p0"]
stiffness = { value = 50.0, min = 1.0, max = 500.0 }
damping = 0.3
anchor = [0.1, -0.05, 0.0]

[[bond]]
kind = "unary"
particles = ["p2"]
stiffness = 20.0
anchor = { value = [0.7, 0.0, -0.1], min = -1.0, max = 1.0 }
anchor_velocity = [0.0, 0.0, 0.0]

[[bond]]
kind = "binary"
particles = ["p0", "p1"]
type = "link"
stiffness = { value = 150.0, min = 1.0, max = 2000.0 }
rest_length = 0.3
damping = 0.2

[[bond]]
kind = "binary"
particles = ["p1", "p2"]
type = "link"
stiffness = { value = 150.0, min = 1.0, max = 2000.0 }
rest_length = 0.3
damping = 0.2

[[bond]]
kind = "ternary"
particles = ["p0", "p1", "p2"]
stiffness = 2.0
rest_angle = 3.0
optional = true
present = false
"""


def chain2d_without_flexion():
    """examples/chain2d.toml (2D, gravity, an anchored first particle) without its ternary
    bonds, the last particle thrown sideways."""
    data = tomllib.loads((EXAMPLES / "chain2d.toml").read_text())
    data["bond"] = [b for b in data["bond"] if b["kind"] != "ternary"]
    data["particle"][-1]["velocity"] = [0.0, 0.5]
    return parse_model(data, "chain2d-binary")


def mujoco_run(xml: str, n_particles: int, dim: int, substeps: int, rk4_step=None):
    """[FRAMES, P, D] positions of the exported model, from its keyframe 'initial'."""
    model = mujoco.MjModel.from_xml_string(xml)
    if rk4_step is not None:
        model.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4
        model.opt.timestep = rk4_step
        substeps = round(1.0 / (RATE * rk4_step))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    xs = [data.qpos.reshape(n_particles, dim).copy()]
    for _ in range(FRAMES - 1):
        for _ in range(substeps):
            mujoco.mj_step(model, data)
        xs.append(data.qpos.reshape(n_particles, dim).copy())
    return np.array(xs)


@pytest.mark.parametrize("which", ["triangle", "chain3d", "chain2d"])
def test_exported_model_moves_as_the_model(which):
    model = {
        "triangle": lambda: load_model(TRIANGLE),
        "chain3d": lambda: loads_model(CHAIN3D, "chain3d"),
        "chain2d": chain2d_without_flexion,
    }[which]()
    n, dim = len(model.spec.particle), model.dimension
    xml = to_mjcf(model, rate=RATE, substeps=SUBSTEPS)

    # the same integrator and step: the same numbers up to rounding
    euler = simulate(model, FRAMES, RATE, substeps=SUBSTEPS).positions
    np.testing.assert_allclose(mujoco_run(xml, n, dim, SUBSTEPS), euler, rtol=0, atol=1e-9)

    # RK4 at a fine step against Verlet: the forces agree (1 mm over 100 frames)
    fine = simulate(model, FRAMES, RATE, substeps=FINE, integrator="verlet").positions
    assert np.abs(fine - fine[0]).max() > 0.1  # it moves (by more than 10 cm)
    rk4 = mujoco_run(xml, n, dim, SUBSTEPS, rk4_step=RK4_STEP)
    assert np.abs(rk4 - fine).max() < 1e-3


def test_mujoco_reads_the_parameters():
    model = loads_model(CHAIN3D, "chain3d")
    m = mujoco.MjModel.from_xml_string(to_mjcf(model, rate=50.0, substeps=4))
    assert m.opt.timestep == pytest.approx(1 / 200)
    assert m.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
    np.testing.assert_allclose(m.opt.gravity, [0.0, 0.0, -9.81])
    np.testing.assert_allclose(m.body_mass[1:], [0.5, 0.7, 0.4])
    assert m.njnt == 9 and (m.jnt_type == mujoco.mjtJoint.mjJNT_SLIDE).all()
    np.testing.assert_allclose(m.qpos0, [0.0, 0.0, 0.0, 0.3, 0.0, 0.05, 0.6, 0.1, 0.0])
    # p0's two anchors: stiffness 250, springref the k-weighted mean anchor, damping 0.8
    np.testing.assert_allclose(m.jnt_stiffness, [250.0] * 3 + [0.0] * 3 + [20.0] * 3)
    np.testing.assert_allclose(m.qpos_spring[:3], [0.02, -0.01, 0.04])
    np.testing.assert_allclose(m.qpos_spring[6:], [0.7, 0.0, -0.1])
    np.testing.assert_allclose(m.dof_damping, [0.8] * 3 + [0.0] * 6)
    # two tendons (the absent ternary bond is left out), one spring length each
    np.testing.assert_allclose(m.tendon_stiffness, [150.0, 150.0])
    np.testing.assert_allclose(m.tendon_damping, [0.2, 0.2])
    np.testing.assert_allclose(m.tendon_lengthspring, [[0.3, 0.3], [0.3, 0.3]])
    np.testing.assert_allclose(m.key_qvel[0], [0.1, 0, 0, 0, 0, 0, 0, -0.2, 0.3])
    assert m.ngeom == 0 and m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    # without a rate: MuJoCo's default step
    assert mujoco.MjModel.from_xml_string(to_mjcf(model)).opt.timestep == pytest.approx(0.002)


@pytest.mark.parametrize(
    ("path", "named"),
    [
        ("horse_limb.toml", ["3 neural bonds (bond[0], bond[1], bond[2])"]),
        ("chain2d.toml", ["3 ternary bonds (bond[5], bond[6], bond[7])"]),
        ("horse_trot_drive.toml", ["4 neural bonds", "4 contact bonds"]),
    ],
)
def test_refuses_what_mujoco_cannot_express(tmp_path, path, named):
    out = tmp_path / "model.xml"
    with pytest.raises(InputError) as err:
        write_mjcf(load_model(EXAMPLES / path), out, source=path)
    line = err.value.line()
    assert "\n" not in line and line.startswith(f"{path}: cannot export to MJCF")
    for text in named:
        assert text in line
    assert not out.exists() and not list(tmp_path.iterdir())


def test_refuses_a_moving_anchor_and_a_missing_position():
    moving = CHAIN3D.replace("anchor_velocity = [0.0, 0.0, 0.0]", "anchor_velocity = [0.1, 0, 0]")
    with pytest.raises(InputError, match=r"1 unary bond with a moving anchor .*\(bond\[2\]\)"):
        to_mjcf(loads_model(moving))
    nowhere = CHAIN3D.replace("position = [0.3, 0.0, 0.05]\n", "")
    with pytest.raises(InputError, match="1 of [0-9]+ particles have no position \\('p1'\\)"):
        to_mjcf(loads_model(nowhere))


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_cli_writes_the_file_and_nothing_on_refusal(tmp_path):
    out = tmp_path / "triangle.xml"
    proc = cli("export", TRIANGLE, "--format", "mjcf", "--out", out, "--rate", "100")
    assert proc.returncode == 0, proc.stderr
    assert out.read_text() == to_mjcf(load_model(TRIANGLE), rate=100.0)
    mujoco.MjModel.from_xml_path(str(out))

    refused = tmp_path / "limb.xml"
    proc = cli("export", EXAMPLES / "horse_limb.toml", "--format", "mjcf", "--out", refused)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "3 neural bonds" in proc.stderr
    proc = cli("export", TRIANGLE, "--format", "urdf", "--out", refused)
    assert proc.returncode == 2
    assert proc.stderr.strip() == "error: --format: expected mjcf, got 'urdf'"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["triangle.xml"]


def test_export_from_a_recording_starts_with_the_velocity_that_lands_on_the_next_frame(tmp_path):
    """``export --from TRAJ --frame 0``, as documented: the velocity from which the model's
    step lands on frame 1, not the forward difference. A triangle damped strongly for its
    100 Hz frames (c dt / m = 3), where the cheap fixed point diverges: Newton's method finds
    the recording's own start velocity, MuJoCo from the exported keyframe lands on frame 1,
    and the command says how the velocity was found. (It wrote the forward difference here,
    silently: 0.28 m/s off.)"""
    import re

    from activebonds.data import write_trajectory
    from helpers import cli_in_process

    text = re.sub(r"damping = \{[^}]*\}", "damping = 300.0", TRIANGLE.read_text())
    model = loads_model(text)
    recording = simulate(model, 20, RATE)
    write_trajectory(recording, tmp_path / "rec.csv")
    (tmp_path / "damped.toml").write_text(text)
    out = tmp_path / "damped.xml"
    proc = cli_in_process(
        "export",
        tmp_path / "damped.toml",
        "--out",
        out,
        "--rate",
        RATE,
        "--from",
        tmp_path / "rec.csv",
        "--frame",
        "0",
    )
    assert proc.returncode == 0, proc.stderr
    assert (
        "initial velocities at frame 0: the velocity from which the model's step lands on the "
        "next frame (by Newton's method: the step's damping is strong for the frame rate)"
    ) in proc.stdout
    m = mujoco.MjModel.from_xml_path(str(out))
    qvel = m.key_qvel.reshape(3, 3)
    _, truth = model.initial_state()
    np.testing.assert_allclose(qvel, truth, rtol=0, atol=1e-6)  # the CSV's rounding
    forward = (recording.positions[1] - recording.positions[0]) * RATE
    assert np.abs(forward - truth).max() > 0.2
    landed = mujoco_run(out.read_text(), 3, 3, 1)[1]
    np.testing.assert_allclose(landed, recording.positions[1], rtol=0, atol=1e-6)


def _ground_model(z=0.05, vx=0.0, k=1e4, c=50.0, mu=0.8, dimension=3):
    """Two particles over the plane z = 0 (y = 0 in 2D) under gravity, each with a ground
    contact: P (2 kg) dropped from ``z`` with velocity ``vx`` along x, Q (1 kg) beside it."""
    up = "[0.0, 0.0, 1.0]" if dimension == 3 else "[0.0, 1.0]"
    g = "[0.0, 0.0, -9.81]" if dimension == 3 else "[0.0, -9.81]"

    def at(x, h):
        return f"[{x}, 0.0, {h}]" if dimension == 3 else f"[{x}, {h}]"

    def vel(v):
        return f"[{v}, 0.0, 0.0]" if dimension == 3 else f"[{v}, 0.0]"

    text = f'name = "ground"\ndimension = {dimension}\ngravity = {g}\n'
    for name, mass, x, v in (("P", 2.0, 0.0, vx), ("Q", 1.0, 1.0, 0.0)):
        text += (
            f'\n[[particle]]\nname = "{name}"\nmass = {mass}\nposition = {at(x, z)}\n'
            f"velocity = {vel(v)}\n"
        )
    for name in ("P", "Q"):
        text += (
            f'\n[[bond]]\nkind = "contact"\ntype = "ground"\nparticles = ["{name}"]\n'
            f"normal = {up}\nheight = 0.0\nstiffness = {k}\ndamping = {c}\nfriction = {mu}\n"
        )
    return loads_model(text)


def _mujoco_frames(xml: str, frames: int, substeps: int, n: int, dim: int) -> np.ndarray:
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    out = [data.qpos.reshape(n, dim).copy()]
    for _ in range(frames - 1):
        for _ in range(substeps):
            mujoco.mj_step(model, data)
        out.append(data.qpos.reshape(n, dim).copy())
    return np.array(out)


def test_ground_contacts_export_as_mujoco_contact_pairs():
    """A contact bond -> a plane geom (one per distinct plane, lowered by the spheres' radius)
    and a sphere on the particle, joined by an explicit contact pair: solref = (-k / m,
    -c / m), the direct stiffness and damping per kg; the least impedance; the bond's
    friction on an elliptic cone, applied by the no-slip solver; no other collision."""
    from activebonds.export.mjcf import IMPEDANCE, SPHERE

    model = _ground_model(k=2e4, c=60.0, mu=0.7)
    m = mujoco.MjModel.from_xml_string(to_mjcf(model, rate=100.0, substeps=10))
    assert m.ngeom == 3 and m.npair == 2
    assert (m.geom_contype == 0).all() and (m.geom_conaffinity == 0).all()
    assert not m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and m.opt.noslip_iterations == 10
    plane = m.geom("ground0")
    assert plane.type == mujoco.mjtGeom.mjGEOM_PLANE
    np.testing.assert_allclose(plane.pos, [0.0, 0.0, -SPHERE])
    assert m.geom("P_sphere").size[0] == SPHERE
    for i, mass in enumerate((2.0, 1.0)):
        np.testing.assert_allclose(m.pair_solref[i], [-2e4 / mass, -60.0 / mass])
        np.testing.assert_allclose(m.pair_solimp[i][:2], [IMPEDANCE, IMPEDANCE])
        np.testing.assert_allclose(m.pair_friction[i][:2], [0.7, 0.7])
        assert m.pair_dim[i] == 3 and m.pair_margin[i] == 0.0


def test_a_particle_resting_on_the_ground_settles_where_it_does_in_our_simulator():
    """Dropped from 5 cm, each particle settles (3 s, 100 Hz, 10 substeps) at the depth where
    its contact holds its weight, m g / k: 1.962 mm (P, 2 kg) and 0.981 mm (Q) at k = 1e4.
    MuJoCo's soft contact passes the unconstrained accelerations on scaled by 1 - d, d its
    impedance (here MuJoCo's least, 1e-4), so its depth is (1 - d) m g / k, 0.2 micrometre
    shallower: within 1 micrometre of ours (measured 2e-7 m)."""
    model = _ground_model()
    ours = simulate(model, 300, 100.0, substeps=10).positions
    theirs = _mujoco_frames(to_mjcf(model, rate=100.0, substeps=10), 300, 10, 2, 3)
    rest = -9.81 * np.array([2.0, 1.0]) / 1e4
    np.testing.assert_allclose(ours[-1, :, 2], rest, rtol=0, atol=1e-9)
    np.testing.assert_allclose(theirs[-1, :, 2], ours[-1, :, 2], rtol=0, atol=1e-6)
    assert np.abs(theirs[-1, :, 2] - rest).max() == pytest.approx(1e-4 * 0.001962, rel=0.05)
    # 2D: the plane y = 0 as a line, the same depths
    flat = _ground_model(dimension=2)
    ours2 = simulate(flat, 300, 100.0, substeps=10).positions
    theirs2 = _mujoco_frames(to_mjcf(flat, rate=100.0, substeps=10), 300, 10, 2, 2)
    np.testing.assert_allclose(theirs2[-1, :, 1], ours2[-1, :, 1], rtol=0, atol=1e-6)


def test_mujoco_moves_a_contact_as_our_simulator_does_one_step_per_frame():
    """Stepped as our one-step explicit Euler (1 kHz, one step per frame), the drop and its
    bounces agree within a micrometre over 3 s (their laws agree term for term: a spring-
    damper pushing only, per kg), and a particle sliding at 0.5 m/s on mu = 0.3 stops
    within 0.2 mm of ours (ours smooths Coulomb's friction below 1 mm/s, MuJoCo's no-slip
    solver does not; measured 0.13 mm)."""
    drop = _ground_model(c=5.0)
    ours = simulate(drop, 3000, 1000.0).positions
    theirs = _mujoco_frames(to_mjcf(drop, rate=1000.0), 3000, 1, 2, 3)
    assert np.abs(ours[:, :, 2]).max() > 0.04  # it bounced
    np.testing.assert_allclose(theirs, ours, rtol=0, atol=1e-6)
    slide = _ground_model(z=-0.0019, vx=0.5, mu=0.3)
    ours = simulate(slide, 300, 1000.0).positions
    theirs = _mujoco_frames(to_mjcf(slide, rate=1000.0), 300, 1, 2, 3)
    stop = 0.25 / (2 * 0.3 * 9.81)  # v^2 / (2 mu g)
    assert ours[-1, 0, 0] == pytest.approx(stop, rel=0.01)
    assert abs(theirs[-1, 0, 0] - ours[-1, 0, 0]) < 2e-4
    assert theirs[:, 0, 2].max() < 0.0  # not lifted off the plane while sliding


def test_a_scaffold_on_the_ground_exports_with_its_contacts(tmp_path):
    """``scaffold`` adds ground contacts for a body standing on the ground; ``export`` now
    writes them (it refused every contact): one pair per foot, and MuJoCo loads the file."""
    from activebonds.data import Trajectory
    from activebonds.identify.discover.scaffold import scaffold

    rng = np.random.default_rng(0)
    frames = 200
    feet = np.array([[0.3, 0.2, 0.02], [0.3, -0.2, 0.02], [-0.3, 0.2, 0.02], [-0.3, -0.2, 0.02]])
    top = np.array([[0.3, 0.0, 0.6], [-0.3, 0.0, 0.55]])
    t = np.arange(frames)[:, None, None] / 100.0
    x = np.concatenate([feet, top])[None] + np.zeros((frames, 1, 3))
    x[:, 4:, 2:] += 0.01 * np.sin(2 * np.pi * t[:, :, :1])  # the body sways above its feet
    x += rng.normal(0, 2e-4, x.shape)
    names = ("FL", "FR", "HL", "HR", "Withers", "Sacrum")
    made = scaffold(Trajectory(x, np.ones((frames, 6), bool), names, 100.0), up="+Z")
    assert made.contacts == 4
    path = tmp_path / "standing.toml"
    path.write_text(made.text)
    out = tmp_path / "standing.xml"
    proc = cli("export", path, "--out", out, "--rate", "100")
    assert proc.returncode == 0, proc.stderr
    m = mujoco.MjModel.from_xml_path(str(out))
    assert m.npair == 4 and [m.geom(m.pair_geom2[i]).name for i in range(4)] == [
        f"{n}_sphere" for n in names[:4]
    ]
