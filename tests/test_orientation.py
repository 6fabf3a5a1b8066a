"""The vertical axis and ground level guessed from a recording (``activebonds info``)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from activebonds.data import Trajectory, read_trajectory
from activebonds.data.orientation import guess_ground

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
    table = subprocess.run([str(exe), "info", str(csv)], capture_output=True, text=True)
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
    """Hooves missing in about 30 % of the frames: there the head is the lowest marker along
    -Z, and the per-frame minimum along -Z (the head's height) is flatter than along +Z, so
    the guess turns upside down, clearly so by its flatness score alone. The frames with every
    marker say +Z: the guess says '(uncertain: ...)' and why, and is not confident."""
    from activebonds.data import describe
    from activebonds.data.orientation import confident, guess_gravity

    whole = guess_ground(_overground())
    assert (whole.axis, whole.up, whole.clear, whole.doubts) == (2, 1.0, True, ())
    gappy = _overground(0.3)
    g = guess_ground(gappy)
    assert (g.axis, g.up) == (2, -1.0) and g.lowest == "Head"  # upside down
    assert g.clear  # the flatness alone does not see it
    assert any("the frames with every marker say up = +Z" in d for d in g.doubts)
    assert "(uncertain: markers missing in" in g.describe()
    gravity = guess_gravity(gappy)
    assert not confident(g, gravity)
    info = describe(gappy)
    assert info["vertical_confident"] is False
    assert "uncertain" in info["ground"]["text"] and "up = +Z" in info["ground"]["text"]


def test_the_vertical_is_uncertain_without_a_second_guess():
    """No flight phase on a treadmill trot: the vertical rests on one guess and says so."""
    from activebonds.data.orientation import confident, guess_gravity, vertical_doubts

    t = _overground()
    g, gravity = guess_ground(t), guess_gravity(t)
    assert not gravity.found
    assert vertical_doubts(g, gravity) == ["no flight phase to check it against"]
    assert g.describe(gravity).endswith("(uncertain: no flight phase to check it against)")
    assert not confident(g, gravity)
