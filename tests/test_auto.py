"""``activebonds auto``: from a recording to an evaluated model in one command
(the package auto/)."""

from __future__ import annotations

import html
import json

import pytest

from activebonds import auto
from activebonds.data.bundled import dataset
from activebonds.identify.judge.burn_in import BurnIn
from activebonds.identify.judge.verdict import comparisons_from
from activebonds.model import load_model
from activebonds.simulation import simulate_to_file
from helpers import cli_in_process

FILES = ("scaffold.toml", "structure.toml", "structure.json", "evaluation.json", "report.html")


@pytest.fixture(scope="module")
def triangle(tmp_path_factory):
    """The triangle example simulated: 300 frames at 60 Hz (no gravity: a free body)."""
    path = tmp_path_factory.mktemp("auto") / "triangle.csv"
    simulate_to_file(dataset("triangle.toml").path, 300, 60.0, path, None, 1, "euler")
    return path


def test_the_window_split_and_its_limits():
    split = auto.windows(600, (0, None), 0.2)
    assert split.fitted == (0, 480) and split.held_out == (480, 600)
    assert auto.windows(600, (100, 300), 0.25).held_out == (250, 300)
    for frames, share, option in [
        ((0, None), 1.5, "--held-out"),
        ((0, None), 0.0, "--held-out"),
        ((0, 15), 0.2, "--frames"),  # 12 fitted, 3 held out
        ((700, None), 0.2, "--frames"),
    ]:
        with pytest.raises(Exception) as err:
            auto.windows(600, frames, share)
        assert option in str(err.value)


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_auto_from_a_simulated_recording_to_a_verdict(triangle, tmp_path):
    out = tmp_path / "out"
    args = ("auto", triangle, "--out", out, "--no-gravity", "--generations", "20")
    args += ("--population", "16")
    proc = cli_in_process(*args)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    n = len(auto.STEPS.names())
    assert n == 5
    for k, step in enumerate(auto.STEPS.names(), 1):
        assert any(line.startswith(f"[{k}/{n}] {step}: ") for line in lines), step
    last = lines[-1]
    assert last.startswith("verdict, held-out frames 240:300: one step: better than zero force")
    assert "10 frames ahead: better than zero force" in last
    for name in FILES:
        assert (out / name).is_file(), name
    assert (out / "run" / "best_model.toml").is_file()
    # the three springs of the truth are found, with the truth's mass ratios (1 : 1.5 : 2:
    # those conserving momentum), and beat zero force on the held-out frames
    found = load_model(out / "structure.toml")
    masses = [p.mass.value if hasattr(p.mass, "value") else p.mass for p in found.spec.particle]
    assert masses == pytest.approx([2 / 3, 1.0, 4 / 3], rel=1e-3)  # 1 kg a marker in all
    springs = [b for b in found.spec.bond if len(b.particles) == 2]
    anchors = [b for b in found.spec.bond if len(b.particles) == 1]  # candidates, or none
    assert len(springs) == 3 and all(not b.absent for b in springs)
    assert all(b.absent for b in anchors)
    record = json.loads((out / "structure.json").read_text())
    assert len(record["choice"]["variants"]) == 18  # chosen on the tail 192:240
    assert record["choice"]["tail_frames"] == [192, 240]
    held = json.loads((out / "evaluation.json").read_text())["held_out"]
    assert held["frames"] == [240, 300]
    one, ahead = held["comparisons"]
    assert one["model_mm"] < 0.5 * one["zero_force_mm"]
    assert ahead["horizon"] == 10 and ahead["model_mm"] < 0.5 * ahead["zero_force_mm"]
    # free runs after a 10-frame burn-in on the held-out frames: the model's state from the
    # frames before each start, then the run, beside zero force's line through them
    after = held["burn_in"]
    assert after["frames"] == 10 and after["horizon"] == 49  # 60 frames: 49 after 11
    assert after["model_mm"][9] < 0.5 * after["zero_force_mm"][9]
    said = BurnIn.from_record(after).lines()[0]
    assert said.startswith("free runs after a 10-frame burn-in") and said in proc.stdout
    # the report says the held-out verdicts the terminal said: the evaluation's, both kinds
    report = html.unescape((out / "report.html").read_text(encoding="utf-8"))
    assert said in report and "The held-out frames' free runs after a burn-in" in report
    for c in comparisons_from(held["comparisons"]):
        for line in c.lines("frames beyond the fit 240:300"):
            assert line in report, line
    state = json.loads((out / "auto.json").read_text())
    assert set(state["steps"]) == set(auto.STEPS.names())
    # ... and how the model was made: the noise's line and the first three steps' notes
    made = report.split('<section id="made"><h2>How this model was made</h2>')[1]
    made = made.split("</section>")[0]
    for name in ("scaffold", "structure", "fit"):
        assert f"{name}: {state['steps'][name]['note']}" in made, name
    assert "marker noise about" in made
    assert state["fitted_frames"] == [0, 240] and state["held_out_frames"] == [240, 300]

    # the same command again: every step kept, the same verdict
    again = cli_in_process(*args)
    assert again.returncode == 0, again.stderr
    assert "continuing" in again.stdout and again.stdout.count("done before") == 3 + 2
    assert again.stdout.strip().splitlines()[-1] == last
    # other options: refused in one line, the folder as it was
    other = cli_in_process(*args, "--seed", "1")
    assert other.returncode == 2 and "--overwrite" in other.stderr
    assert len(other.stderr.strip().splitlines()) == 1


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_too_many_candidates_are_kept_undecided(triangle, tmp_path, monkeypatch):
    monkeypatch.setattr(auto.structure, "MAX_DECIDED", 2)
    out = tmp_path / "out"
    proc = cli_in_process(
        "auto", triangle, "--out", out, "--no-gravity", "--generations", "5",
        "--population", "8", "--ahead", "5",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert "6 candidate bonds, more than 2: no elimination" in proc.stdout
    record = json.loads((out / "structure.json").read_text())
    assert record["eliminated"] is False and record["decisions"] == []
    assert all(b.present for b in load_model(out / "structure.toml").spec.bond)
    assert "5 frames ahead" in proc.stdout.strip().splitlines()[-1]


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--held-out", "1.5"], "--held-out"),
        (["--markers", "A,Nope"], "Nope"),
        (["--total-mass", "-1"], "--total-mass"),
        (["--population", "2"], "--population"),
        (["--ahead", "0"], "--ahead"),
        (["--frames", "0:12"], "--frames"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(triangle, tmp_path, options, message):
    out = tmp_path / "out"
    proc = cli_in_process("auto", triangle, "--out", out, "--no-gravity", *options)
    assert proc.returncode == 2, proc.stdout
    assert proc.stderr.startswith("error: ") and len(proc.stderr.strip().splitlines()) == 1
    assert message in proc.stderr
    assert not out.exists()


def test_a_folder_of_something_else_is_refused(triangle, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "mine.txt").write_text("keep")
    proc = cli_in_process("auto", triangle, "--out", out, "--no-gravity", "--overwrite")
    assert proc.returncode == 2 and "not a folder of activebonds auto" in proc.stderr
    assert [p.name for p in out.iterdir()] == ["mine.txt"]


def test_the_last_verdict_says_when_one_step_scores_are_the_noise_s():
    from types import SimpleNamespace

    from activebonds.auto import NOISY_ONE_STEP, Outcome

    def comparison(what, text):
        return SimpleNamespace(what=what, overall=SimpleNamespace(text=lambda: text))

    held = SimpleNamespace(
        frames=(321, 401),
        comparisons=(
            comparison("one step", "better than zero force by 26.5 % (1.592 vs 2.166 mm)"),
            comparison("10 frames ahead", "better than zero force by 58.1 % (5.649 vs 13.48 mm)"),
        ),
    )
    for window, said in ((7, True), (0, False)):
        state = {"noise": {"sigma": 0.54, "window": window}}
        line = Outcome(None, state, held, None).verdict()
        assert line.startswith("verdict, held-out frames 321:401: one step: better")
        assert (NOISY_ONE_STEP in line) == said
        assert line.index("10 frames ahead") > (line.index(NOISY_ONE_STEP) if said else 0)
