"""Mistakes a new user made on recordings of their own, each answered by one line that names
the real mistake: exit 2, nothing written, no traceback (a CSV with another separator, a
dimension every vector disagrees with, MODEL and DATA swapped, a bond's place in the file,
--cost's values); and the free run's advice, which names a rhythmic drive only for a
recording that repeats itself."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers import EXAMPLES, TRIANGLE, both_ways_fresh_in_slow, cli_in_process

TRIANGLE_CSV = EXAMPLES / "triangle.csv"


def one_line_refusal(proc, *words: str) -> str:
    """The one line of a refused command (exit 2), which holds every one of ``words``."""
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    line = lines[0]
    assert line.startswith("error: "), line
    for w in words:
        assert w in line, (w, line)
    return line


def nothing_written(folder: Path, before: set[str]) -> None:
    assert {p.name for p in folder.iterdir()} == before


# -------------------------------------------------------------------- 1. the CSV's separator


# in this process; in a fresh one too (its whole stderr: no traceback) in `pytest -m slow`
@pytest.mark.parametrize(*both_ways_fresh_in_slow())
@pytest.mark.parametrize(
    "sep, named", [(";", "';'"), ("\t", "tabs"), ("|", "'|'")], ids=["semicolon", "tab", "bar"]
)
def test_a_csv_with_another_separator_says_so(tmp_path, run, sep, named):
    data = tmp_path / "semi.csv"
    data.write_text(TRIANGLE_CSV.read_text().replace(",", sep))
    before = {p.name for p in tmp_path.iterdir()}
    line = one_line_refusal(
        run("fit", TRIANGLE, data, "--out", tmp_path / "run"),
        str(data),
        "line 3",  # the header, after the two comment lines
        f"seems to use {named} as its separator",
        "comma",
    )
    assert "has columns for axes" not in line
    nothing_written(tmp_path, before)
    one_line_refusal(run("info", data), f"seems to use {named} as its separator")


def test_a_trc_file_named_csv_is_told_to_be_renamed(tmp_path):
    trc = "PathFileType\t4\t(X/Y/Z)\tx.trc\nDataRate\tCameraRate\n100\t100\n"
    data = tmp_path / "walk.csv"
    data.write_text(trc)
    one_line_refusal(cli_in_process("info", data), "line 1", "TRC file", ".trc")


# ------------------------------------------------------- 2. a dimension the vectors disagree with


def test_a_dimension_every_vector_disagrees_with_is_named(tmp_path):
    text = TRIANGLE.read_text().replace("dimension = 3", "dimension = 2\ngravity = [0, 0, -9.81]")
    model = tmp_path / "m_dim.toml"
    model.write_text(text)
    before = {p.name for p in tmp_path.iterdir()}
    line = one_line_refusal(
        cli_in_process("fit", model, TRIANGLE_CSV, "--out", tmp_path / "run"),
        str(model),
        "dimension = 2 but gravity, every particle position and every particle velocity have "
        "3 components: is dimension right?",
    )
    assert "expected 2 components" not in line
    nothing_written(tmp_path, before)


def test_one_vector_of_the_wrong_length_is_still_named_itself(tmp_path):
    """Only when every vector agrees on another length is the dimension blamed."""
    text = TRIANGLE.read_text().replace("dimension = 3", "dimension = 3\ngravity = [0, -9.81]")
    model = tmp_path / "m.toml"
    model.write_text(text)
    line = one_line_refusal(
        cli_in_process("evaluate", model, TRIANGLE_CSV), "gravity: expected 3 components, got 2"
    )
    assert "is dimension right" not in line
    # a lone vector (no particle position given): it may be the mistake as well
    from activebonds.errors import InputError
    from activebonds.model.io import loads_model

    lone = 'dimension = 3\ngravity = [0.0, -9.81]\n[[particle]]\nname = "A"\nmass = 1.0\n'
    with pytest.raises(InputError) as info:
        loads_model(lone, "lone.toml")
    assert str(info.value) == "lone.toml: gravity: expected 3 components, got 2"


# --------------------------------------------------------------- 3. MODEL and DATA swapped

SWAPPED = [
    ("fit", ["--out", "run"]),
    ("evaluate", []),
    ("fill", ["--out", "filled.csv"]),
    ("structure", ["--out", "s.toml"]),
    ("baselines", []),
]


@pytest.mark.parametrize(*both_ways_fresh_in_slow())
@pytest.mark.parametrize("command, options", SWAPPED, ids=[c for c, _ in SWAPPED])
def test_swapped_model_and_data_are_named_with_the_order(tmp_path, run, command, options):
    model, data = tmp_path / "m.toml", tmp_path / "noisy.csv"
    model.write_text(TRIANGLE.read_text())
    data.write_text(TRIANGLE_CSV.read_text())
    before = {p.name for p in tmp_path.iterdir()}
    opts = [
        str(tmp_path / o) if o.endswith((".csv", ".toml")) or o == "run" else o for o in options
    ]
    line = one_line_refusal(
        run(command, data, model, *opts),
        "the arguments look swapped",
        f"activebonds {command} MODEL DATA",
    )
    assert "not valid TOML" not in line
    nothing_written(tmp_path, before)


@pytest.mark.parametrize(
    "argv, words",
    [
        (["fit", "{data}", "{data}", "--out", "{run}"], ["{data}", "a recording where the model"]),
        (["fit", "{model}", "{model}", "--out", "{run}"], ["{model}", "a model file where a"]),
        (
            ["export", "{data}", "--format", "mjcf", "--out", "{xml}"],
            ["{data}", "activebonds export MODEL"],
        ),
        (
            ["simulate", "{data}", "--n-frames", "5", "--rate", "100", "--out", "{out}"],
            ["{data}", "activebonds simulate MODEL"],
        ),
    ],
    ids=["fit-data-data", "fit-model-model", "export-data", "simulate-data"],
)
def test_a_recording_for_a_model_or_a_model_for_a_recording(tmp_path, argv, words):
    model, data = tmp_path / "m.toml", tmp_path / "noisy.csv"
    model.write_text(TRIANGLE.read_text())
    data.write_text(TRIANGLE_CSV.read_text())
    before = {p.name for p in tmp_path.iterdir()}
    names = {"data": data, "model": model, "run": tmp_path / "run"}
    names |= {"xml": tmp_path / "m.xml", "out": tmp_path / "out.csv"}
    proc = cli_in_process(*(a.format(**names) for a in argv))
    one_line_refusal(proc, *(w.format(**names) for w in words))
    nothing_written(tmp_path, before)


# ---------------------------------------------------------- 4. a bond's place in the model file


def test_a_bond_error_names_the_line_and_count_of_its_block(tmp_path):
    text = TRIANGLE.read_text()
    third = [i for i, line in enumerate(text.splitlines(), 1) if line == "[[bond]]"][2]
    lines = text.splitlines()
    k = next(i for i in range(third, len(lines)) if lines[i].startswith("stiffness"))
    lines[k] = lines[k].replace("stiffness", "stifness", 1)
    model = tmp_path / "m_key.toml"
    model.write_text("\n".join(lines) + "\n")
    before = {p.name for p in tmp_path.iterdir()}
    one_line_refusal(
        cli_in_process("fit", model, TRIANGLE_CSV, "--out", tmp_path / "run"),
        f"{model}: line {third} (the 3rd [[bond]]): bond[2].stifness: unknown key",
    )
    nothing_written(tmp_path, before)


def test_ordinals_and_a_file_whose_blocks_cannot_be_counted():
    """The count is said as people say it; where the file's [[bond]] headers are not one per
    bond (an inline array of tables), no line is made up."""
    from activebonds.errors import InputError
    from activebonds.model.io import _ordinal, loads_model

    said = [_ordinal(n) for n in (1, 2, 3, 4, 11, 12, 13, 21, 22, 101, 111)]
    assert said == [
        "1st",
        "2nd",
        "3rd",
        "4th",
        "11th",
        "12th",
        "13th",
        "21st",
        "22nd",
        "101st",
        "111th",
    ]
    inline = (
        'dimension = 2\nparticle = [{ name = "A", mass = 1.0 }, { name = "B", mass = 1.0 }]\n'
        'bond = [{ kind = "binary", particles = ["A", "Z"], stiffness = 1.0, rest_length = 1.0 }]\n'
    )
    with pytest.raises(InputError) as info:
        loads_model(inline, "inline.toml")
    assert str(info.value) == "inline.toml: bond[0].particles: unknown particle 'Z'"


# ------------------------------------------------------------------------ 5. --cost's values


def test_cost_lists_every_accepted_value(tmp_path):
    before = {p.name for p in tmp_path.iterdir()}
    line = one_line_refusal(
        cli_in_process(
            "fit", TRIANGLE, TRIANGLE_CSV, "--out", tmp_path / "run", "--cost", "shootng"
        ),
        "--cost: expected auto, restart or shooting, got 'shootng'",
    )
    assert "Input should be" not in line
    nothing_written(tmp_path, before)


# ----------------------------------------------------- 6. the free run's advice: a drive or not

RATE = 100.0
FRAMES = 200


def _write_csv(path: Path, x: np.ndarray) -> None:
    """Markers A, B, C [F, 3, 3] (m) as the triangle's CSV (mm)."""
    head = "Frame#,Time," + ",".join(f"{m}{a}" for m in "ABC" for a in "XYZ")
    rows = [
        ",".join([str(f + 1), repr(f / RATE), *(f"{1000.0 * v:.6f}" for v in x[f].ravel())])
        for f in range(x.shape[0])
    ]
    path.write_text(f"# units: mm\n# rate: {RATE}\n{head}\n" + "\n".join(rows) + "\n")


def _shape() -> np.ndarray:
    return np.array([[0.0, 0.0, 0.0], [0.55, 0.0, 0.05], [0.2, 0.45, 0.0]])


def thrown(path: Path) -> None:
    """A body thrown up from 0.6 m: it flies, lands (ground at 0), slides and stops."""
    t = np.arange(FRAMES) / RATE
    z = np.maximum(0.6 + 1.0 * t - 4.905 * t**2, 0.0)
    x = 2.0 * (1.0 - np.exp(-t / 0.5)) * 0.5
    _write_csv(path, _shape()[None] + np.stack([x, 0 * t, z], 1)[:, None, :])


def trotting(path: Path) -> None:
    """A body bobbing up and down every 25 frames as it moves on (a gait's vertical rhythm),
    each marker a little out of phase."""
    t = np.arange(FRAMES) / RATE
    phase = np.array([0.0, 0.8, 1.6])
    z = 0.3 + 0.04 * np.sin(2 * np.pi * 4.0 * t[:, None] + phase)  # [F, 3]
    x = 1.2 * t
    pos = np.repeat(_shape()[None], FRAMES, 0)
    pos[:, :, 0] += x[:, None]
    pos[:, :, 2] += z
    _write_csv(path, pos)


def falling_model(path: Path) -> None:
    """The triangle with gravity and nothing to hold it: its free run falls metres."""
    path.write_text(
        TRIANGLE.read_text().replace("dimension = 3", "dimension = 3\ngravity = [0.0, 0.0, -9.81]")
    )


@pytest.mark.parametrize(
    "make, repeats",
    [(thrown, False), (trotting, True)],
    ids=["thrown-no-drive", "trotting-drive"],
)
def test_the_free_run_advice_names_a_drive_only_for_a_recording_that_repeats(
    tmp_path, make, repeats
):
    from activebonds.data import read_trajectory
    from activebonds.data.period import recording_period

    data, model = tmp_path / "rec.csv", tmp_path / "m.toml"
    make(data)
    falling_model(model)
    period = recording_period(read_trajectory(data).positions, None, [0.0, 0.0, 1.0])
    if repeats:
        assert period == pytest.approx(25.0, abs=0.5)
    else:
        assert np.isnan(period)
    proc = cli_in_process("evaluate", model, data)
    assert proc.returncode == 0, proc.stderr
    advice = [line for line in proc.stdout.splitlines() if line.startswith("advice:")]
    assert len(advice) == 1, proc.stdout
    assert "the body falls; add ground contacts (activebonds scaffold writes them)" in advice[0]
    assert "anchors (unary springs)" in advice[0]
    assert ("rhythmic drive" in advice[0]) is repeats, advice[0]


def test_the_advice_without_gravity_for_a_body_that_repeats_nothing():
    from activebonds.identify.judge.verdict import free_run_advice

    bare = {"gravity": False, "contacts": 0, "anchors": 0, "drive": False, "repeats": False}
    assert free_run_advice(2000.0, bare) == (
        "advice: the free run ends 2 m (RMS) from the recording: nothing holds the body (the "
        "recording does not repeat itself: no rhythmic drive); add anchors (unary springs) or "
        "gravity with ground contacts (activebonds scaffold writes them)"
    )
    anchored = {**bare, "anchors": 2}
    assert "although the model has anchors: make them stiffer" in free_run_advice(2000.0, anchored)
    assert "rhythmic drive" not in free_run_advice(2000.0, anchored)
    contacts = {**bare, "gravity": True, "contacts": 3}
    assert "rhythmic drive" not in free_run_advice(2000.0, contacts)
    assert "rhythmic drive" in free_run_advice(2000.0, {**contacts, "repeats": True})
    assert "rhythmic drive" in free_run_advice(2000.0, {**contacts, "repeats": None})  # unknown


@pytest.mark.slow
def test_a_tiny_fit_on_a_thrown_body_advises_no_drive(tmp_path):
    """The fit's own summary (its baselines stage) says the same as evaluate."""
    data, model = tmp_path / "rec.csv", tmp_path / "m.toml"
    thrown(data)
    falling_model(model)
    proc = cli_in_process(
        "fit",
        model,
        data,
        "--out",
        tmp_path / "run",
        *("--generations", "2", "--population", "8", "--refine", "none", "--cost", "restart"),
    )
    assert proc.returncode == 0, proc.stderr
    advice = [line for line in proc.stdout.splitlines() if line.startswith("advice:")]
    assert advice and all("rhythmic drive" not in a for a in advice), proc.stdout


def test_backwards_frames_are_said_as_typed(tmp_path):
    """`--frames 5:1` said '(5, 1)', a Python tuple; the line says what was typed."""
    before = {p.name for p in tmp_path.iterdir()}
    one_line_refusal(
        cli_in_process("fit", TRIANGLE, TRIANGLE_CSV, "--out", tmp_path / "run", "--frames", "5:1"),
        "--frames: frames must be START:STOP with 0 <= START < STOP, got 5:1",
    )
    nothing_written(tmp_path, before)
