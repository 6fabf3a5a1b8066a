"""Where the data is (coverage, gap-free windows), what the gaps cost a fit, and the vertical
guessed from gravity in flight (``activebonds info``, ``activebonds fit``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from activebonds.data import Trajectory, describe, read_trajectory, write_trajectory
from activebonds.data.coverage import count_gaps, coverage, longest, present_windows
from activebonds.data.orientation import G, guess_gravity
from activebonds.errors import InputError
from activebonds.identify.costs.windows import count_predictions, make_windows
from helpers import EXAMPLES, HORSE_TROT, TRIANGLE, both_ways_fresh_in_slow

HORSE_WALK = HORSE_TROT.with_name("Horse1_M1_walk1_kinematics.csv")


def _invoke(*args):
    from activebonds.cli.main import app

    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "300"})


# ----------------------------------------------------------------------------- windows


@pytest.mark.parametrize(
    ("mask", "min_len", "expected"),
    [
        ([1, 1, 0, 1, 1, 1, 0, 0, 1], 1, [(0, 2), (3, 6), (8, 9)]),
        ([1, 1, 0, 1, 1, 1, 0, 0, 1], 2, [(0, 2), (3, 6)]),
        ([1, 1, 0, 1, 1, 1, 0, 0, 1], 3, [(3, 6)]),
        ([1, 1, 0, 1, 1, 1, 0, 0, 1], 4, []),
        ([0, 0, 0], 1, []),
        ([1, 1, 1, 1, 1], 1, [(0, 5)]),
        ([0, 1, 1, 0], 1, [(1, 3)]),
        ([[1, 1], [1, 0], [1, 1], [1, 1], [0, 1]], 1, [(0, 1), (2, 4)]),  # all of a set
    ],
)
def test_present_windows_of_hand_made_masks(mask, min_len, expected):
    assert present_windows(np.array(mask, bool), min_len) == expected


def test_longest_first_and_gap_counts():
    windows = [(0, 2), (3, 6), (8, 11), (20, 21)]
    assert longest(windows, 2) == [(3, 6), (8, 11)]  # equal lengths: the earlier first
    assert longest(windows) == [(3, 6), (8, 11), (0, 2), (20, 21)]
    assert count_gaps(np.array([0, 1, 0, 0, 1, 0], bool)) == 3
    assert count_gaps(np.ones(4, bool)) == 0


def _ten_frames() -> Trajectory:
    """A missing at frames 2-3, B at frame 7, C always present."""
    mask = np.ones((10, 3), bool)
    mask[2:4, 0] = False
    mask[7, 1] = False
    x = np.random.default_rng(0).normal(size=(10, 3, 3))
    x[~mask] = np.nan
    return Trajectory(positions=x, mask=mask, markers=("A", "B", "C"), rate=100.0)


def test_coverage_numbers():
    c = coverage(_ten_frames(), ["A", "C"])
    a, b, cc = (c["markers"][m] for m in "ABC")
    assert (a["present"], a["missing_frames"], a["gaps"]) == (0.8, 2, 1)
    assert (b["present"], b["missing_frames"], b["gaps"]) == (0.9, 1, 1)
    assert (cc["present"], cc["missing_frames"], cc["gaps"]) == (1.0, 0, 0)
    assert a["longest"] == {"frames": "4:10", "start": 4, "stop": 10, "length": 6}
    assert b["longest"]["frames"] == "0:7" and cc["longest"]["frames"] == "0:10"
    # all three present in frames 0, 1, 4, 5, 6, 8, 9
    assert c["all"]["present"] == pytest.approx(0.7)
    assert [w["frames"] for w in c["all"]["windows"]] == ["4:7", "0:2", "8:10"]
    assert c["chosen"]["markers"] == ["A", "C"]
    assert c["chosen"]["present"] == pytest.approx(0.8)
    assert [(w["frames"], w["length"]) for w in c["chosen"]["windows"]] == [("4:10", 6), ("0:2", 2)]
    assert coverage(_ten_frames())["chosen"] is None


def test_info_markers_windows(tmp_path):
    path = tmp_path / "ten.csv"
    write_trajectory(_ten_frames(), path)
    res = _invoke("info", path, "--json", "--markers", "B,C")
    assert res.exit_code == 0, res.output
    chosen = json.loads(res.stdout)["coverage"]["chosen"]
    assert chosen["markers"] == ["B", "C"]
    assert [(w["frames"], w["length"]) for w in chosen["windows"]] == [("0:7", 7), ("8:10", 2)]
    table = _invoke("info", path, "--markers", "B,C")
    assert table.exit_code == 0, table.output
    assert "B,C present" in table.stdout and "0:7 (7 frames), 8:10 (2 frames)" in table.stdout
    assert "longest gap-free window" in table.stdout  # the per-marker coverage table
    bad = _invoke("info", path, "--markers", "B,Nope")
    assert bad.exit_code == 2 and "Nope" in bad.output
    with pytest.raises(InputError, match="Nope"):
        describe(_ten_frames(), ["Nope"])


# ----------------------------------------------------------------------------- fit and gaps


@pytest.fixture(scope="module")
def gappy(tmp_path_factory):
    """The triangle's recording (120 frames) with B missing at frame 10 and A at 30-31."""
    t = read_trajectory(EXAMPLES / "triangle.csv")
    mask = t.mask.copy()
    mask[10, 1] = False
    mask[30:32, 0] = False
    x = t.positions.copy()
    x[~mask] = np.nan
    path = tmp_path_factory.mktemp("gappy") / "gappy.csv"
    write_trajectory(t.with_positions(x, mask), path)
    return path


def test_the_count_is_the_costs(gappy):
    """By hand, frames 0:50: starts s = 1..48 each predict frame s + 1 of 3 markers (144).
    A start needs frames s - 1 and s complete: B's gap (10) kills s = 10, 11 (6 predictions),
    A's (30, 31) s = 30, 31, 32 (9); the targets B at 10 (from s = 9) and A at 30 (from s = 29)
    remove one each: 17 removed, 127 left."""
    w = read_trajectory(gappy).window(0, 50)
    assert count_predictions(w.mask, 1) == (127, 144)
    for horizon in (1, 2, 5, 48):
        kept, possible = count_predictions(w.mask, horizon)
        assert kept == make_windows(w.positions, w.mask, w.dt, horizon).n_terms
        assert possible == 48 * 3  # every frame from the third on is predicted once


def _no_fit(*args, **kwargs):
    raise AssertionError("the fit started")


def test_fit_says_what_the_gaps_removed(gappy, tmp_path, monkeypatch):
    """The line comes before the fit (stopped here: the fit's own run is not this test's)."""
    import activebonds.identify

    def stop(*args, **kwargs):
        raise InputError("test", "stopped before the fit")

    monkeypatch.setattr(activebonds.identify, "fit", stop)
    res = _invoke("fit", TRIANGLE, gappy, "--frames", "0:50", "--out", tmp_path / "run")
    assert res.exit_code == 2 and "stopped before the fit" in res.output
    assert "gaps removed 17 of 144 predictions (12 %) in frames 0:50" in res.stdout
    full = _invoke("fit", TRIANGLE, gappy, "--frames", "32:", "--out", tmp_path / "run")
    assert "gaps removed 0 of 258 predictions (0 %) in frames 32:120" in full.stdout


@pytest.mark.parametrize(*both_ways_fresh_in_slow())
def test_fit_refuses_a_window_with_too_few_predictions(gappy, tmp_path, run):
    """Frames 28:36 (A missing at 30, 31): 8 of 18 predictions left, 24 coordinates for the
    neural triangle's 27 parameters. One line, exit 2, no run directory, nothing compiled."""
    out = tmp_path / "run"
    proc = run("fit", TRIANGLE, gappy, "--frames", "28:36", "--bonds", "neural", "--out", out)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    line = lines[0]
    assert line.startswith("error: --frames: gaps removed 10 of 18 predictions")
    assert "24 coordinates for the model's 27 free parameters" in line
    assert "32:120 (88 frames), 11:30 (19 frames), 0:10 (10 frames)" in line
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_fit_refuses_a_window_without_predictions(gappy, tmp_path, monkeypatch):
    """Frames 29:34: every start needs a frame where A is missing; refused before the fit."""
    import activebonds.identify

    monkeypatch.setattr(activebonds.identify, "fit", _no_fit)
    res = _invoke("fit", TRIANGLE, gappy, "--frames", "29:34", "--out", tmp_path / "run")
    assert res.exit_code == 2, res.output
    assert "gaps removed 9 of 9 predictions (100 %)" in res.output
    assert "the 0 left give 0 coordinates" in res.output and "32:120 (88 frames)" in res.output
    assert not (tmp_path / "run").exists()


# ----------------------------------------------------------------------------- gravity


def _thrown(gravity, frames=120, rate=100.0, seed=0) -> Trajectory:
    """Five points thrown against ``gravity`` (m/s^2) from around one place, 1 mm noise."""
    rng = np.random.default_rng(seed)
    g = np.asarray(gravity, float)
    t = np.arange(frames)[:, None, None] / rate
    x0 = rng.normal(0.0, 0.2, (5, 3))
    v0 = rng.normal(0.0, 1.0, (5, 3)) - 0.3 * g  # upwards at about 3 m/s
    x = x0 + v0 * t + 0.5 * g * t**2 + rng.normal(0.0, 0.001, (frames, 5, 3))
    return Trajectory(
        positions=x, mask=np.ones((frames, 5), bool), markers=tuple("abcde"), rate=rate
    )


@pytest.mark.parametrize(
    ("gravity", "axis", "up"), [((0, -G, 0), 1, 1.0), ((0, 0, G), 2, -1.0), ((-G, 0, 0), 0, 1.0)]
)
def test_gravity_of_points_thrown(gravity, axis, up):
    g = guess_gravity(_thrown(gravity))
    assert g.found and (g.axis, g.up) == (axis, up)
    assert g.along_up == pytest.approx(-G, abs=0.05)
    assert g.phases == 1 and g.flight_frames > 60


def test_no_flight_no_gravity_guess():
    """The bundled horse walk: a hoof always on the ground, so no guess, and it says so."""
    g = guess_gravity(read_trajectory(HORSE_WALK))
    assert not g.found and g.describe().startswith("none (no flight phase found")
    d = describe(read_trajectory(HORSE_WALK))
    assert d["gravity"]["up"] is None and d["gravity"]["text"].startswith("none")
    assert d["vertical_agree"] is None and d["ground"]["up"] == "+Z"
    assert d["vertical_confident"] is False and "(uncertain: no flight phase" in d["ground"]["text"]


def _hopper(rate=100.0) -> Trajectory:
    """Four markers (foot on the ground, hip, head, hand) of a body that stands 30 frames and
    hops at 2 m/s, three times, drifting along X and swaying along Z; Y up."""
    flight = np.arange(1, int(2 * 2 / G * rate)) / rate
    hop = 2 * flight - 0.5 * G * flight**2
    y = np.concatenate([np.zeros(30), hop] * 3 + [np.zeros(30)])
    t = np.arange(len(y)) / rate
    body = np.array([[0, 0, 0], [0.05, 0.9, 0.02], [0.0, 1.5, -0.03], [0.2, 1.0, 0.1]])
    x = np.repeat(body[None], len(y), axis=0)
    x[:, :, 0] += t[:, None]
    x[:, :, 1] += y[:, None]
    x[:, :, 2] += 0.05 * np.sin(2 * np.pi * t)[:, None]
    x += np.random.default_rng(1).normal(0.0, 0.0005, x.shape)
    markers = ("foot", "hip", "head", "hand")
    return Trajectory(positions=x, mask=np.ones(x.shape[:2], bool), markers=markers, rate=rate)


def test_info_shows_both_vertical_guesses(tmp_path):
    path = tmp_path / "hop.csv"
    write_trajectory(_hopper(), path)
    res = _invoke("info", path, "--json")
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["ground"]["up"] == "+Y" and d["gravity"]["up"] == "+Y"
    assert d["gravity"]["normal"] == [0.0, 1.0, 0.0] and d["gravity"]["phases"] == 3
    assert d["gravity"]["along_up"] == pytest.approx(-G, abs=0.1)
    assert d["vertical_agree"] is True
    assert d["vertical_confident"] is True and "uncertain" not in d["ground"]["text"]
    table = _invoke("info", path)
    assert "vertical from gravity (guessed)" in table.stdout
    assert "up = +Y: the markers accelerate at -9.8" in table.stdout
    assert "the two vertical guesses" in table.stdout and "agree" in table.stdout
