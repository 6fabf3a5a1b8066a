"""What limits `auto`'s verdict, said after it: held-out frames that hardly move, masses the
fit did not identify; and contradictory options refused."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from activebonds.auto import STILL, fixed_masses_note, still_note
from activebonds.errors import InputError
from activebonds.identify.discover.scaffold import scaffold
from activebonds.identify.judge.verdict import Verdict
from activebonds.model import load_model
from activebonds.simulation import simulate

ROOT = Path(__file__).resolve().parents[1]
TRIANGLE = ROOT / "examples" / "triangle.toml"


def _scored(frames, model_mm, zero_mm):
    return SimpleNamespace(frames=frames, verdict=Verdict(model_mm, zero_mm))


def test_held_out_frames_at_rest_are_said_to_judge_little():
    """A held-out tail whose zero-force error is under a tenth of the fitted frames' (a body
    come to rest: 0.01147 vs 2.8 mm) gets the note, with both figures; one that moves does
    not, nor does a tail exactly at the threshold."""
    fitted = _scored((0, 640), 1.9, 2.8)
    note = still_note(_scored((640, 801), 0.1183, 0.01147), fitted)
    assert note.startswith("note: frames 640:801 hardly move")
    assert "0.01147 mm there" in note and "2.8 mm on the fitted frames" in note
    assert still_note(_scored((640, 801), 3.0, 2.5), fitted) is None
    assert still_note(_scored((640, 801), 1.0, STILL * 2.8), fitted) is None
    assert still_note(SimpleNamespace(frames=(0, 1), verdict=None), fitted) is None


def test_fixed_masses_are_said_to_scale_every_stiffness(tmp_path):
    """The triangle's masses are fixed (1, 1.5, 2 kg): the note names them (equal ones once);
    the same model with its masses free under total_mass gets none."""
    run = tmp_path / "run"
    run.mkdir()
    text = TRIANGLE.read_text()
    (run / "best_model.toml").write_text(text)
    note = fixed_masses_note(run)
    assert note.startswith("masses: not identified (")
    assert "(A 1, B 1.5, C 2 kg)" in note
    assert "every stiffness and damping is relative to them" in note
    equal = text.replace("mass = 1.5", "mass = 1.0").replace("mass = 2.0", "mass = 1.0")
    (run / "best_model.toml").write_text(equal)
    assert "(1 kg each)" in fixed_masses_note(run)
    # after a flight's fit that was not kept: what happened, not how to try
    tried = fixed_masses_note(run, tmp_path / "run-flight")
    assert "the flight's fit (run-flight) did not identify them well enough" in tried
    assert "free the masses" not in tried and "free the masses" in fixed_masses_note(run)
    free = text.replace("mass = 1.0", "mass = { value = 1.0, min = 0.1, max = 10.0 }")
    free = free.replace("mass = 1.5", "mass = { value = 1.5, min = 0.1, max = 10.0 }")
    free = free.replace("mass = 2.0", "mass = { value = 2.0, min = 0.1, max = 10.0 }")
    (run / "best_model.toml").write_text(f"total_mass = 4.5\n{free}")
    assert any(load_model(run / "best_model.toml").spec.free_masses())
    assert fixed_masses_note(run) is None


def test_up_and_no_gravity_together_are_refused():
    data = simulate(load_model(TRIANGLE), 20, 100.0)
    with pytest.raises(InputError, match="--up Z names gravity's vertical and --no-gravity"):
        scaffold(data, up="Z", gravity=False)


def test_frames_beyond_the_recording_are_refused_as_fit_evaluate_and_fill_refuse_them(tmp_path):
    """`auto --frames 1100:5000` on a 1,200-frame file ran on 1100:1199 and exited 0; now one
    rule (data.trajectory.frame_window) refuses it for every command, in one line, and nothing
    is written."""
    from activebonds.auto.folder import windows
    from activebonds.data import write_trajectory
    from helpers import cli_in_process

    with pytest.raises(InputError, match=r"window stop 5000 is out of range for 1200 frames"):
        windows(1200, (1100, 5000), 0.2)
    split = windows(1200, (1100, None), 0.2)
    assert (split.fitted, split.held_out) == ((1100, 1180), (1180, 1200))
    data = tmp_path / "tri.csv"
    write_trajectory(simulate(load_model(TRIANGLE), 40, 100.0), data)
    out = tmp_path / "out"
    for argv in (
        ("auto", data, "--out", out, "--frames", "10:500"),
        ("evaluate", TRIANGLE, data, "--frames", "10:500"),
    ):
        done = cli_in_process(*argv)
        assert done.returncode == 2, done.stderr
        assert "window stop 500 is out of range for 40 frames (0..40)" in done.stderr
    assert not out.exists()


def test_markers_never_present_in_the_held_out_tail_are_said_before_fitting():
    from activebonds.auto.notes import absent_note

    data = simulate(load_model(TRIANGLE), 60, 100.0)
    positions = data.positions.copy()
    positions[45:, 1] = np.nan  # the second marker gone from frame 45 on
    cut = data.with_positions(positions)
    markers = list(data.markers)
    assert absent_note(data, markers, (48, 60)) is None
    line = absent_note(cut, markers, (48, 60))
    assert line.startswith(
        f"note: 1 of 3 markers never present in the held-out frames 48:60 ({markers[1]})"
    )
    assert absent_note(cut, markers, (40, 60)) is None  # present in 40:44


def test_auto_prints_the_uncertainty_warnings_as_a_count_and_leaves_their_words_to_the_report():
    """The uncertainty's warnings advise refits (--cost shooting, --substeps 4) that `auto`
    decides itself: its summary counts them in one line; the report has their words."""
    from activebonds.auto.workspace import printed_lines

    lines = [
        "zero-force baseline on the same frames 0.1009 mm",
        "uncertainty: 9 of 9 parameters determined",
        "uncertainty: warning: these intervals come from the one-step cost: refit with --cost shooting",
        "uncertainty: warning: at --substeps 4 the parameters move: refit with --substeps 4",
    ]
    printed = printed_lines(lines)
    assert printed[:2] == lines[:2] and not any("refit" in p for p in printed)
    assert (
        printed[-1]
        == "uncertainty: 2 warnings on these intervals, in the report's Uncertainty section"
    )
    assert printed_lines(lines[:2]) == lines[:2]
