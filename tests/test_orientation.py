"""The vertical axis and ground level guessed from a recording (``activebonds info``)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from activebonds.data import Trajectory, read_trajectory
from activebonds.data.orientation import guess_ground
from helpers import cli_in_process

HORSE = Path(__file__).resolve().parents[1] / "src" / "activebonds" / "datasets" / "horse_vhdc"


@pytest.mark.parametrize(
    "name", ["Horse1_M1_trot1_kinematics.csv", "Horse1_M1_walk1_kinematics.csv"]
)
def test_the_horse_stands_on_z_up_at_ground_level(name):
    """The VHDC treadmill recordings: z up, hooves at about 0 m (their lowest: -1 cm)."""
    g = guess_ground(read_trajectory(HORSE / name))
    assert g.axis == 2 and g.up == 1.0 and g.clear
    assert -0.02 < g.height < 0.0
    assert g.lowest.startswith("H") and g.lowest not in ("Head",)
    assert g.normal == [0.0, 0.0, 1.0] and g.plane_height == pytest.approx(g.height)


@pytest.mark.parametrize("axis, sign", [(0, -1.0), (1, 1.0), (1, -1.0)])
def test_a_turned_recording_is_read_the_right_way_up(axis, sign):
    """The trot with its axes permuted and flipped: the guess follows the data."""
    t = read_trajectory(HORSE / "Horse1_M1_trot1_kinematics.csv")
    perm = [0, 1]  # new axis i holds old axis perm[i]: z goes to `axis`, x and y keep order
    perm.insert(axis, 2)
    x = t.positions[:, :, perm].copy()
    x[:, :, axis] *= sign
    turned = Trajectory(positions=x, mask=t.mask, markers=t.markers, rate=t.rate)
    g = guess_ground(turned)
    assert (g.axis, g.up) == (axis, sign) and g.clear
    assert sign * g.height == pytest.approx(guess_ground(t).height, abs=1e-12)


def test_info_shows_the_guess(tmp_path):
    exe = Path(sys.executable).with_name("activebonds")
    csv = HORSE / "Horse1_M1_trot1_kinematics.csv"
    proc = subprocess.run([str(exe), "info", str(csv), "--json"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    ground = json.loads(proc.stdout)["ground"]
    assert ground["up"] == "+Z" and ground["normal"] == [0.0, 0.0, 1.0]
    assert ground["height"] == pytest.approx(guess_ground(read_trajectory(csv)).height)
    # the table in this process (the fresh process's own output is the JSON's above)
    table = cli_in_process("info", csv)
    assert table.returncode == 0, table.stderr
    assert "up = +Z, ground at -0.0105 m" in table.stdout


def test_a_human_walk_from_opensim_is_y_up():
    """OpenSim's convention (y up), found from the data alone: 41 markers over the walk, the
    lowest a toe marker a few centimetres above the floor (marker radius and shoe)."""
    trc = Path(__file__).resolve().parent / "data" / "human_opensim" / "subject01_walk1.trc"
    g = guess_ground(read_trajectory(trc))
    assert (g.axis, g.up) == (1, 1.0) and g.clear
    assert 0.0 < g.height < 0.06
    assert "Toe" in g.lowest or "Heel" in g.lowest


def _overground(gaps: float = 0.0) -> Trajectory:
    """The treadmill trot carried forward at 3 m/s (overground: the lowest marker along x
    moves, so z is clearly the flattest axis), its hooves missing in a share ``gaps`` of the
    frames (blocks of 5)."""
    t = read_trajectory(HORSE / "Horse1_M1_trot1_kinematics.csv")
    x = np.array(t.positions)
    x[:, :, 0] += 3.0 * np.arange(t.n_frames)[:, None] / t.rate
    mask = np.array(t.mask)
    hooves = [i for i, m in enumerate(t.markers) if m.startswith("H") and m != "Head"]
    rng = np.random.default_rng(1)
    for f in range(0, t.n_frames, 5):
        if rng.random() < gaps:
            x[f : f + 5, hooves] = np.nan
            mask[f : f + 5, hooves] = False
    return Trajectory(positions=x, mask=mask, markers=t.markers, rate=t.rate)


def test_an_upside_down_guess_through_gaps_is_flagged_uncertain():
    """Hooves missing in about 30 % of the frames. When every frame's lowest marker counted,
    there the head was the lowest along -Z and the guess turned upside down; the ground is now
    the lowest *foot* of each frame where a foot is present, so the guess stays +Z. A guess
    that the frames with every marker contradict (here the -Z one, made by hand) still says
    '(uncertain: ...)' and why, and is not confident."""
    from dataclasses import replace

    from activebonds.data.orientation import confident, ground_doubts, guess_gravity

    whole = guess_ground(_overground())
    assert (whole.axis, whole.up, whole.clear, whole.doubts) == (2, 1.0, True, ())
    gappy = _overground(0.3)
    g = guess_ground(gappy)
    assert (g.axis, g.up, g.clear, g.doubts) == (2, 1.0, True, ())
    assert g.feet == ("HFL", "HFR", "HHL", "HHR")
    assert g.height == pytest.approx(whole.height, abs=0.002)
    flipped = replace(g, up=-1.0, doubts=())
    doubts = ground_doubts(gappy, flipped)
    share = 100 * (1 - np.asarray(gappy.mask).all(axis=1).mean())
    assert doubts == (
        f"markers missing in {share:.0f} % of frames; the frames with every marker say up = +Z",
    )
    flipped = replace(flipped, doubts=doubts)
    assert "(uncertain: markers missing in" in flipped.describe()
    assert not confident(flipped, guess_gravity(gappy))


def test_the_vertical_is_uncertain_without_a_second_guess():
    """No flight phase on a treadmill trot: the vertical rests on one guess and says so."""
    from activebonds.data.orientation import confident, guess_gravity, vertical_doubts

    t = _overground()
    g, gravity = guess_ground(t), guess_gravity(t)
    assert not gravity.found
    assert vertical_doubts(g, gravity) == ["no flight phase to check it against"]
    assert g.describe(gravity).endswith("(uncertain: no flight phase to check it against)")
    assert not confident(g, gravity)


FEET = ("FL", "FR", "HL", "HR")
TORSO = ("Withers", "Sacrum", "Belly", "Top")


def _quadruped(
    dip: float | None = None, roll: float = 0.0, level_top: bool = False, seed: int = 0
) -> Trajectory:
    """A simulated quadruped walking along +X at 1 m/s, z up: four foot markers 2 cm above the
    ground in stance (half of each 1 s stride, the legs in a walk's sequence), 8 cm up at mid
    swing, and four torso markers about 0.5 m up, the body swaying 5 cm sideways at the stride.
    ``roll``: the feet markers rise by up to this much within their stance (markers above the
    sole, rolling with the hoof). ``dip``: the Belly marker drops to this height (below the
    feet) in 4 runs of 8 frames (8 % of the 400 frames: a swapped label, a stumble).
    ``level_top``: the Top marker (the extreme along +Y) keeps its sideways coordinate, not
    swaying with the body."""
    rate, frames = 100.0, 400
    t = np.arange(frames) / rate
    rng = np.random.default_rng(seed)
    x = np.zeros((frames, 8, 3))
    sway = 0.05 * np.sin(2 * np.pi * t)
    foot_xy = {"FL": (0.5, 0.15), "FR": (0.5, -0.15), "HL": (-0.5, 0.15), "HR": (-0.5, -0.15)}
    for i, (name, phase) in enumerate(zip(FEET, (0.0, 0.5, 0.75, 0.25), strict=True)):
        s = np.sin(2 * np.pi * (t + phase))
        swing = np.clip(s, 0, None)
        stance = np.clip(-s, 0, None)
        u = (t + phase) % 1.0  # stance for u in [0.5, 1): the foot stays put on the ground
        ahead = np.where(u < 0.5, -0.25 + u, 0.25 - (u - 0.5))  # along x from the body
        x[:, i, 0] = t + foot_xy[name][0] + ahead
        x[:, i, 1] = foot_xy[name][1] + sway
        x[:, i, 2] = 0.02 + 0.06 * swing + roll * stance
    body = {"Withers": (0.45, 0.0, 0.55), "Sacrum": (-0.45, 0.0, 0.5), "Belly": (0.0, -0.05, 0.4)}
    for j, name in enumerate(TORSO[:3], start=4):
        bx, by, bz = body[name]
        x[:, j] = [bx, by, bz] + np.stack([t, sway, 0.01 * np.sin(4 * np.pi * t)], axis=1)
    top_y = 0.4 + (0.0 if level_top else sway)
    x[:, 7] = np.stack([t, top_y + 0 * t, 0.6 + 0.01 * np.sin(4 * np.pi * t)], axis=1)
    x += rng.normal(0, 0.0005, x.shape)
    if dip is not None:
        for start in (40, 140, 240, 340):
            x[start : start + 8, 6, 2] = dip
    return Trajectory(positions=x, mask=np.ones((frames, 8), bool), markers=FEET + TORSO, rate=rate)


def test_a_torso_marker_that_dips_lowest_in_a_few_frames_is_not_the_ground():
    """The Belly marker drops 5 cm below the feet in 8 % of the frames: the ground stays at the
    feet (2 cm up), which are the four foot markers; the scaffold's contacts are the feet, not
    the Belly. (The 5th percentile of every frame's lowest marker put the ground at the
    Belly's dip, -3 cm, and the Belly alone within reach of it.)"""
    from activebonds.identify.discover.scaffold import scaffold

    traj = _quadruped(dip=-0.03)
    g = guess_ground(traj)
    assert (g.axis, g.up) == (2, 1.0) and g.clear
    assert g.feet == FEET
    assert g.height == pytest.approx(0.02, abs=0.0015)
    assert g.against == "" and g.doubts == ()
    made = scaffold(traj, up="+Z")
    assert made.contacts == 4
    touching = re.findall(r'kind = "contact"\ntype = "ground"\nparticles = \["(\w+)"\]', made.text)
    assert touching == list(FEET)
    assert (
        f"contacts: 4 marker(s) within 2 cm of the ground (at {g.height:.4g} m along up) in at "
        "least 5 % of the frames"
    ) in made.notes


def test_a_ground_on_one_marker_against_several_feet_is_uncertain():
    """The feet roll 3 cm within their stance, so the lowest foot of each frame moves, while the
    Top marker keeps its sideways coordinate: along -Y the per-frame extreme (Top alone) is the
    flattest, clearly, and with no flight phase nothing checks it. The feet cue disagrees: along
    +Z four markers reach the lowest height often. The vertical is uncertain, and the
    scaffold adds no gravity (it pointed sideways, along +Y, before)."""
    from activebonds.data.orientation import confident, guess_gravity, vertical_doubts
    from activebonds.identify.discover.scaffold import scaffold

    traj = _quadruped(roll=0.03, level_top=True)
    g, gravity = guess_ground(traj), guess_gravity(traj)
    assert (g.axis, g.up) == (1, -1.0) and g.clear and g.feet == ("Top",)
    assert not gravity.found
    why = (
        "the ground rests on Top alone, but along +Z 4 markers (FL, FR, HL, HR) reach the "
        "lowest height in at least 10 % of their frames"
    )
    assert g.against == why
    assert vertical_doubts(g, gravity) == [why, "no flight phase to check it against"]
    assert not confident(g, gravity)
    assert g.describe().endswith(f"(uncertain: {why})")
    made = scaffold(traj)
    assert made.gravity == "none" and made.contacts == 0
    assert any(
        n.startswith("gravity: none (the vertical is uncertain") and why in n for n in made.notes
    )


def test_a_flight_that_confirms_the_guess_lifts_the_feet_doubt():
    """The feet cue is a doubt only while nothing else checks the guess: a flight phase whose
    acceleration names the same up clears it."""
    from activebonds.data.orientation import Gravity, vertical_doubts

    g = guess_ground(_quadruped(roll=0.03, level_top=True))
    same = Gravity(1, -1.0, (0.0, 9.81, 0.0), 20, 2)
    assert vertical_doubts(g, same) == []
