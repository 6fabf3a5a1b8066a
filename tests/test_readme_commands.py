"""The README's examples run as written.

Every ``activebonds`` line of the README's Commands block names a command that exists, options
that command has, and input files that exist in a clone (or are written by an earlier line);
the lines up to ``evaluate`` (bundled data, info, simulate, export, fit, baselines, evaluate,
structure) are run in order, from a folder holding only the repository's ``examples``, the fit
shortened to 3 generations of 8; each must exit 0 and print (or write) what it should. The
Python API example's files exist. (The other long jobs, the report, sweep, paper experiments
and demo, have tests of their own and are checked here for their options only.)
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from activebonds.cli.main import app
from activebonds.data.bundled import DATASETS, EXAMPLES, dataset
from helpers import ROOT

README = (ROOT / "README.md").read_text()
INPUTS = (".toml", ".csv", ".trc", ".c3d", ".npz", ".mat")
# Run as written (the long ones shortened): these; the others are checked for options only.
RUN = ("datasets", "info", "simulate", "structure", "export", "fit", "baselines", "evaluate")
SHORTER = {
    "--n-frames": ("simulate", "200"),
    "--population": ("fit", "8"),
    "--generations": ("fit", "3"),
}


def commands_block() -> list[str]:
    """The Commands block's lines, continuation lines joined, comments dropped."""
    block = re.search(r"## Commands\s+```bash\n(.*?)```", README, re.S)
    assert block, "the README has no Commands block"
    text = block.group(1).replace("\\\n", " ")
    lines = []
    for line in text.splitlines():
        line = re.sub(r"\s#\s.*$", "", line).strip()
        if line and not line.startswith("#"):
            lines.append(line)
    return lines


def expand(lines: list[str]) -> list[list[str]]:
    """The ``activebonds`` lines as argument lists, shell variables (``name=$(activebonds
    datasets NAME)`` or ``name=PATH``) substituted."""
    values: dict[str, str] = {}
    out = []
    for line in lines:
        m = re.fullmatch(r"(\w+)=\$\(activebonds datasets ([\w.-]+)\)", line)
        if m:
            values[m.group(1)] = str(dataset(m.group(2)).path)
            out.append(["datasets", m.group(2)])
            continue
        m = re.fullmatch(r"(\w+)=(\S+)", line)
        if m:
            values[m.group(1)] = m.group(2)
            continue
        for name, value in values.items():
            line = line.replace(f"${name}", value)
        args = shlex.split(line)
        assert args[0] == "activebonds", f"not an activebonds line: {line}"
        out.append(args[1:])
    return out


def _help(command: str) -> str:
    res = CliRunner().invoke(app, [command, "--help"], env={"COLUMNS": "300"})
    assert res.exit_code == 0, f"README names an unknown command {command!r}"
    return res.output


def test_every_readme_command_has_its_options_and_inputs():
    commands = expand(commands_block())
    assert len(commands) >= 10
    written: set[str] = set()
    for args in commands:
        help_text = _help(args[0])
        for opt in (a.split("=")[0] for a in args if a.startswith("--")):
            assert opt in help_text, f"activebonds {args[0]} has no option {opt}"
        for i, a in enumerate(args[1:], 1):
            if args[i - 1] == "--out" or args[i - 1].startswith("--"):
                if args[i - 1] == "--out":
                    written.add(a)
                continue
            if a.endswith(INPUTS):
                inside_run = any(Path(a).is_relative_to(w) for w in written)
                assert (ROOT / a).exists() or Path(a).exists() or inside_run, (
                    f"README: activebonds {' '.join(args)}: {a} does not exist"
                )
    # run and resume name the folder a fit writes
    assert {"fit", "resume", "report", "evaluate", "export", "datasets"} <= {c[0] for c in commands}


def _check_output(args: list[str], out: str) -> None:
    """One output of each command run, checked against what it must say or write (the horse
    trot's frames 0:10 have the audit's baselines: zero force 5.6205 mm, momentum floor
    4.1066 mm, exact least squares 4.2026 mm)."""
    from activebonds.data import read_trajectory
    from activebonds.model import load_model

    command = args[0]
    if command == "datasets" and len(args) == 2:
        assert out.strip() == str(dataset(args[1]).path)
    elif command == "datasets":
        assert all(name in out for name in DATASETS) and "example files" in out
    elif command == "info":
        assert re.search(r"frames\s+│\s+600\b", out) and "Head,Withers,HFL present" in out
    elif command == "simulate":
        n = int(args[args.index("--n-frames") + 1])
        path = args[args.index("--out") + 1]
        assert f"wrote {n} frames to {path}" in out
        assert read_trajectory(path).n_frames == n
    elif command == "export":
        assert "3 point masses" in out
        assert (
            Path(args[args.index("--out") + 1]).read_text().startswith('<mujoco model="triangle">')
        )
    elif command == "fit":
        assert "zero-force baseline on the same frames 5.621 mm" in out
        best = float(re.search(r"completed: best RMS error ([\d.]+) mm", out).group(1))
        assert 4.1066 - 1e-3 <= best  # no internal-force model beats the momentum floor
        assert load_model(Path(args[args.index("--out") + 1]) / "best_model.toml").dimension == 3
    elif command == "baselines":
        assert re.search(r"zero force \(constant velocity\)\s+│\s+5\.6205 ", out)
        assert re.search(r"momentum floor \(internal forces\)\s+│\s+4\.1066", out)
        assert re.search(r"exact least squares \(linear parameters\)\s+│\s+4\.2026", out)
    elif command == "evaluate":
        assert f"frames {args[args.index('--frames') + 1]}" in out
        assert re.search(r"one-step RMS \(mm\)\s+│\s+[\d.]+\s+│\s+6\.34115 ", out)
    elif command == "structure":
        assert "3 of 6 present" in out
        assert load_model(args[args.index("--out") + 1]).topology.count("binary") == 3
    else:  # pragma: no cover - RUN names the commands above
        raise AssertionError(f"no output check for {command}")


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_the_cheap_readme_commands_run_as_written(tmp_path, monkeypatch):
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    monkeypatch.chdir(tmp_path)
    ran = []
    for args in expand(commands_block()):
        if args[0] not in RUN:
            continue
        args = [  # the README's long jobs, shortened for the test
            SHORTER[prev][1] if SHORTER.get(prev, ("",))[0] == args[0] else a
            for prev, a in zip(["", *args[:-1]], args, strict=True)
        ]
        res = CliRunner().invoke(app, args, env={"COLUMNS": "300"})
        assert res.exit_code == 0, (args, res.output)
        _check_output(args, res.stdout)
        ran.append(args[0])
    assert set(ran) == set(RUN), ran


def test_the_python_api_example_names_files_that_exist():
    api = re.search(r"## Python API\s+```python\n(.*?)```", README, re.S)
    assert api
    paths = re.findall(r'"([\w./-]+\.(?:toml|csv))"', api.group(1))
    assert paths
    for p in paths:
        assert (ROOT / p).exists(), p


@pytest.mark.parametrize("name", [*DATASETS, *EXAMPLES])
def test_every_bundled_name_resolves_to_a_file(name):
    assert dataset(name).path.is_file()
    if name in DATASETS:  # the licence travels with the data
        assert (dataset(name).path.parent / Path(DATASETS[name].licence).name).is_file()


def test_the_bundled_human_walk_resolves_and_reads_41_markers_151_frames_at_60_hz():
    res = CliRunner().invoke(app, ["datasets", "human-walk"], env={"COLUMNS": "300"})
    assert res.exit_code == 0, res.output
    path = Path(res.stdout.strip())
    assert path == dataset("human-walk").path and path.name == "subject01_walk1.trc"
    assert (path.parent / "PROVENANCE.txt").is_file()
    from activebonds.data import read_trajectory

    walk = read_trajectory(path)
    assert walk.positions.shape == (151, 41, 3) and walk.mask.all()
    assert walk.rate == 60.0 and walk.markers[0] == "R.ASIS" and walk.markers[-1] == "Top.Head"
    # read from mm: the first marker's first frame in metres
    np.testing.assert_allclose(walk.positions[0, 0], [0.61724762, 1.05527502, 0.17078198])
