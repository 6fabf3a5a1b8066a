"""Every code block of the site's tutorial, how-tos and home page runs as written.

The fenced ``bash``/``console``/``python`` blocks of ``docs/index.md``, ``docs/tutorial.md`` and
``docs/howto/*.md`` are read from the pages. Each shell line is an ``activebonds`` command
(shell variables ``name=$(activebonds datasets NAME)`` and ``$(activebonds datasets NAME)``
substituted), run in this process through the real command line (Typer's CliRunner), page
by page in a temporary folder holding a copy of the repository's ``examples``; Python blocks are
exec'd there after the page's shell blocks. The long jobs are shortened: a fit to 2
generations of 8 and at most 5 refinement steps, ``auto`` to 2 generations of 8 on frames
0:150, a sweep's manifest to 2 generations of each fit, run ``--sequential`` (no Ray).
Every command is checked for what it prints or writes (:func:`check`), not only its exit code.

A line that cannot run in a test is in :data:`UNRUNNABLE` with the reason, and
:func:`test_every_block_line_is_run_or_listed_as_unrunnable` asserts that list is exactly the
set of such lines in the pages: a new block cannot escape the tests unnoticed.

The default suite runs the cheap pages (the fits without their refinement) and the
tutorial's first three steps; the whole tutorial, noisy data, ``auto``, the sweep and the fits
with their refinement are ``slow``.
"""

from __future__ import annotations

import math
import re
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from activebonds.cli.main import app
from activebonds.data.bundled import dataset
from helpers import ROOT

DOCS = ROOT / "docs"
PAGES = [
    "index.md",
    "tutorial.md",
    *sorted(str(p.relative_to(DOCS)) for p in DOCS.glob("howto/*.md")),
]
LANGUAGES = ("bash", "console", "python")

# Lines that cannot run in a test, with the reason (each must be in a page, and every line of
# a page's blocks that the runner cannot run must be here).
UNRUNNABLE = {
    "python3 -m venv .venv && . .venv/bin/activate && pip install . && activebonds demo --out demo": (
        "a new virtual environment and an install from the network; the demo has tests of its "
        "own (tests/test_cli_fit.py, tests/test_readme_commands.py)"
    ),
    "python3 -m venv .venv && . .venv/bin/activate && pip install '.[test]' && pytest": (
        "a new virtual environment, an install, and the whole test suite"
    ),
    "pip install 'activebonds[ray]'": "installs a package from the network",
    (
        "activebonds fit DIR/run-ground/best_model.toml DATA --frames START:STOP --init model "
        "--cost shooting --horizon 10 --substeps 4 --integrator verlet --out masses"
    ): (
        "a recipe with placeholders: a model the reader has edited by hand (its masses freed) "
        "and the frames in flight of the reader's recording"
    ),
    "activebonds sweep examples/sweep.toml --out sweeps --address auto": (
        "joins a running Ray cluster (tests/test_sweep.py runs sweeps on a local one)"
    ),
    "activebonds auto trials/*.c3d --out study": (
        "the reader's trials (tests/test_auto_dataset.py runs datasets it makes)"
    ),
    "activebonds auto trials/ --out study --workers 2": (
        "the reader's trials, on Ray (tests/test_auto_dataset.py: --workers=2 against --sequential)"
    ),
    "activebonds auto A.c3d B.c3d C.c3d --out horse --subject": (
        "one subject's trials (tests/test_auto_dataset.py runs --subject on three it makes)"
    ),
    "activebonds auto trials/*.c3d --out study --address auto": (
        "joins a running Ray cluster (tests/test_auto_dataset_cluster.py starts one and "
        "kills its worker node)"
    ),
}


# The pages whose blocks a test below runs (a new page with a runnable block must join them).
RUN_PAGES = {
    "tutorial.md",
    "howto/auto.md",
    "howto/export-mujoco.md",
    "howto/gap-filling.md",
    "howto/noisy-data.md",
    "howto/several-recordings.md",
    "howto/sweeps.md",
}


def blocks(page: str) -> list[tuple[str, str]]:
    """The page's fenced blocks in those languages: (language, text)."""
    text = (DOCS / page).read_text()
    found = re.findall(r"^```(\w+)\n(.*?)^```", text, re.S | re.M)
    return [(lang, body) for lang, body in found if lang in LANGUAGES]


def shell_lines(body: str, language: str) -> list[str]:
    """A shell block's commands: continuation lines joined, comments dropped (``console``:
    the lines after a ``$`` prompt)."""
    text = body.replace("\\\n", " ")
    out = []
    for line in text.splitlines():
        if language == "console":
            if not line.startswith("$ "):
                continue
            line = line[2:]
        line = re.sub(r"\s#\s.*$", "", line).strip()
        if line and not line.startswith("#"):
            out.append(re.sub(r"\s+", " ", line))
    return out


def runnable(line: str) -> bool:
    return bool(
        re.fullmatch(r"\w+=\$\(activebonds datasets [\w.-]+\)", line)
        or line.startswith("activebonds ")
    )


def page_lines(page: str) -> list[str]:
    return [
        line for lang, body in blocks(page) if lang != "python" for line in shell_lines(body, lang)
    ]


def test_every_block_line_is_run_or_listed_as_unrunnable():
    lines = {line for page in PAGES for line in page_lines(page)}
    skipped = {line for line in lines if not runnable(line) or line in UNRUNNABLE}
    assert skipped == set(UNRUNNABLE)  # none unlisted, none listed that the pages lost
    for page in ("tutorial.md", "howto/noisy-data.md", "howto/export-mujoco.md"):
        assert page_lines(page), f"docs/{page} has no command block"
    assert any(lang == "python" for lang, _ in blocks("tutorial.md"))
    with_runnable = {
        page
        for page in PAGES
        if any(line not in UNRUNNABLE for line in page_lines(page))
        or any(lang == "python" for lang, _ in blocks(page))
    }
    assert with_runnable == RUN_PAGES


def test_every_command_of_the_blocks_has_its_options():
    import typer.main

    group = typer.main.get_command(app)
    for page in PAGES:
        for line in page_lines(page):
            if line in UNRUNNABLE:
                continue
            args = shlex.split(re.sub(r"\$\(activebonds datasets [\w.-]+\)", "X", line))
            if args[0] != "activebonds":
                continue
            command = group.commands.get(args[1])
            assert command is not None, f"docs/{page}: no command {args[1]!r}: {line}"
            opts = {o for p in command.params for o in (*p.opts, *p.secondary_opts)}
            for used in (a.split("=")[0] for a in args[2:] if a.startswith("-")):
                assert used in opts, f"docs/{page}: activebonds {args[1]} has no {used}: {line}"


# ------------------------------------------------------------------------------ running


def _value(args: list[str], option: str, default: str | None = None) -> str | None:
    return args[args.index(option) + 1] if option in args else default


def _set(args: list[str], option: str, value: str) -> list[str]:
    if option in args:
        args = list(args)
        args[args.index(option) + 1] = value
        return args
    return [*args, option, value]


def shorten(args: list[str], refine: bool = True) -> list[str]:
    """The long jobs of a page, shortened for the test (the options only, never the files);
    a fit's refinement to 5 steps, or (``refine=False``) none at all (one step where the fit
    names its cost, the refinement's)."""
    if args[0] == "fit":
        args = _set(_set(args, "--generations", "2"), "--population", "8")
        if not refine and "--cost" not in args:
            args = _set(args, "--refine", "none")
        elif _value(args, "--refine") != "none":
            args = _set(args, "--max-steps", "5" if refine else "1")
    elif args[0] == "auto":
        args = _set(_set(args, "--generations", "2"), "--population", "8")
        args = _set(args, "--frames", "0:150")
    elif args[0] == "sweep":
        manifest = Path(args[1])
        text = re.sub(r"(?m)^generations = \d+", "generations = 2", manifest.read_text())
        manifest.write_text(re.sub(r"(?m)^checkpoint_every = \d+", "checkpoint_every = 1", text))
        args = [*args, "--sequential"]
    return args


def expand(line: str, variables: dict[str, str]) -> list[str] | None:
    """The line as the command line's arguments (``activebonds`` dropped), its variables
    substituted; None for an assignment (recorded in ``variables``)."""
    m = re.fullmatch(r"(\w+)=\$\(activebonds datasets ([\w.-]+)\)", line)
    if m:
        variables[m.group(1)] = invoke(["datasets", m.group(2)]).strip()
        return None
    for name in re.findall(r"\$\(activebonds datasets ([\w.-]+)\)", line):
        line = line.replace(f"$(activebonds datasets {name})", invoke(["datasets", name]).strip())
    for name, value in variables.items():
        line = line.replace(f"${name}", value)
    args = shlex.split(line)
    assert args[0] == "activebonds", line
    return args[1:]


def invoke(args: list[str]) -> str:
    res = CliRunner().invoke(app, args, env={"COLUMNS": "200", "NO_COLOR": "1"})
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        raise res.exception
    assert res.exit_code == 0, (args, res.output)
    if args[0] == "datasets" and len(args) == 2:
        assert Path(res.stdout.strip()) == dataset(args[1]).path
    return res.output


def _number(pattern: str, out: str) -> float:
    m = re.search(pattern, out)
    assert m, (pattern, out[-2000:])
    return float(m.group(1))


def check(args: list[str], out: str) -> str:
    """What the command printed or wrote, checked; returns what was checked (for the log)."""
    from activebonds import load_model, read_trajectory

    command, target = args[0], _value(args, "--out")
    if command == "info":
        traj = read_trajectory(args[1])
        assert re.search(rf"frames\s+│\s+{traj.n_frames}\b", out)
        assert all(m in out for m in traj.markers)
        return f"info: {traj.n_frames} frames"
    if command == "scaffold":
        model = load_model(target)
        n = len(read_trajectory(args[1]).markers)
        assert model.topology.n_particles == n
        candidates = int(_number(r"(\d+) candidate springs", out))
        assert candidates >= n - 1
        return f"scaffold: {n} particles, {candidates} candidate springs"
    if command == "structure":
        present = re.search(r"(\d+) of (\d+) present", out)
        assert present, out[-2000:]
        kept = int(present.group(1))
        text = Path(target).read_text()
        assert text.count("present = true") == kept
        assert text.count("present = false") == int(present.group(2)) - kept
        load_model(target)
        assert math.isfinite(_number(r"one-step RMS ([\d.]+) mm", out))
        return f"structure: {kept} of {present.group(2)} present"
    if command == "fit":
        rms = _number(r"completed: best RMS error ([\d.e+-]+) mm", out)
        zero = _number(r"zero-force baseline on the same frames ([\d.]+) mm", out)
        assert 0 < rms < 10 * zero
        run = Path(target)
        load_model(run / "best_model.toml")
        history = (run / "history.csv").read_text().splitlines()
        assert len([h for h in history if h and not h.startswith("#")]) - 1 == int(
            _value(args, "--generations")
        )
        if _value(args, "--refine") != "none":
            assert (run / "uncertainty.csv").is_file() and "refinement 1/" in out
        return f"fit: {rms} mm (zero force {zero} mm)"
    if command == "evaluate":
        one = re.search(r"one-step RMS \(mm\)\s+│\s+([\d.]+)\s+│\s+([\d.]+)", out)
        assert one and all(math.isfinite(float(x)) for x in one.groups()), out[-2000:]
        assert f"frames {_value(args, '--frames')}" in out
        return f"evaluate: one step {one.group(1)} vs zero force {one.group(2)} mm"
    if command == "report":
        page = Path(args[1]) / "report.html"
        assert page.stat().st_size > 10_000
        assert "<html" in page.read_text()[:1000].lower()
        return f"report: {page.stat().st_size} bytes"
    if command == "fill":
        filled = read_trajectory(target)
        source = read_trajectory(args[2])
        assert filled.n_frames == source.n_frames and filled.markers == source.markers
        sidecar = Path(
            _value(args, "--record") or Path(target).with_name(Path(target).stem + ".gaps.csv")
        )
        rows = [r for r in sidecar.read_text().splitlines() if r and not r.startswith("#")]
        assert rows, "no sidecar"
        # every gap filled or listed as left: the samples filled are present in the output
        assert filled.n_gaps + len(rows) - 1 >= source.n_gaps
        assert filled.n_gaps <= source.n_gaps
        return f"fill: {source.n_gaps - filled.n_gaps} of {source.n_gaps} missing filled"
    if command == "export":
        xml = Path(target).read_text()
        assert xml.startswith("<mujoco model=")
        n = load_model(args[1]).topology.n_particles
        assert xml.count("<body ") == n and f"{n} point masses" in out
        return f"export: {n} bodies"
    if command == "simulate":
        n = int(_value(args, "--n-frames"))
        traj = read_trajectory(target)
        assert traj.n_frames == n and traj.rate == float(_value(args, "--rate"))
        assert np.isfinite(traj.positions).all()
        return f"simulate: {n} frames"
    if command == "auto":
        folder = Path(target)
        for name in ("scaffold.toml", "structure.toml", "evaluation.json", "report.html"):
            assert (folder / name).is_file(), name
        load_model(folder / "run" / "best_model.toml")
        assert re.search(r"verdict.*(better|worse|no better) than zero force", out)
        return "auto: every step's file"
    if command == "sweep":
        summary = (Path(target) / "summary.csv").read_text().splitlines()
        assert len(summary) - 1 == 9, summary  # the example's 3 x 2 + 3 fits
        assert (Path(target) / "summary.html").is_file()
        return f"sweep: {len(summary) - 1} fits"
    raise AssertionError(f"no check for activebonds {command}")


def run_page(page: str, folder: Path, *, stop: int | None = None, refine=True) -> list[str]:
    """Run the page's blocks in order in ``folder`` (its first ``stop`` shell commands
    only, if given; the fits without their refinement unless ``refine``); returns what was
    checked."""
    variables: dict[str, str] = {}
    checked = []
    ran = 0
    for lang, body in blocks(page):
        if lang == "python":
            if stop is None:
                checked.append(run_python(page, body))
            continue
        for line in shell_lines(body, lang):
            if line in UNRUNNABLE:
                continue
            if stop is not None and ran >= stop:
                return checked
            args = expand(line, variables)
            if args is None:
                continue
            args = shorten(args, refine)
            out = invoke(args)
            checked.append(check(args, out) if args[0] != "datasets" else "datasets")
            ran += 1
    return checked


def run_python(page: str, body: str) -> str:
    """Exec a Python block, its fits shortened; checks what it binds."""
    code = re.sub(r"generations=\d+", "generations=2, population=8, max_steps=5", body)
    namespace: dict = {}
    exec(compile(code, f"docs/{page}", "exec"), namespace)  # noqa: S102 - the docs' own code
    result = namespace["result"]
    assert math.isfinite(result.rms_mm) and result.rms_mm > 0
    assert result.verdict is not None and math.isfinite(result.baselines["zero_force_rms_mm"])
    out = Path(re.search(r'out="([^"]+)"', body).group(1))
    assert (out / "best_model.toml").is_file()
    return f"python: {result.rms_mm} mm"


@pytest.fixture
def folder(tmp_path, monkeypatch):
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _recording_with_gaps(path: Path) -> None:
    """The triangle's recording with two gaps inside it (marker B 40:46, C 70:75)."""
    from activebonds import read_trajectory, write_trajectory

    traj = read_trajectory(ROOT / "examples" / "triangle.csv")
    positions = np.array(traj.positions)
    positions[40:46, 1] = np.nan
    positions[70:75, 2] = np.nan
    write_trajectory(traj.with_positions(positions), path)


def test_the_export_page_runs(folder):
    assert run_page("howto/export-mujoco.md", folder) == ["export: 3 bodies"]


@pytest.mark.parametrize("refine", [False, True], ids=["es", "refined"])
@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_the_several_recordings_page_runs(folder, refine):
    checked = run_page("howto/several-recordings.md", folder, refine=refine)
    assert checked[:2] == ["simulate: 120 frames"] * 2 and checked[2].startswith("fit: ")


@pytest.mark.slow
def test_the_noisy_data_page_runs(folder):
    checked = run_page("howto/noisy-data.md", folder)
    assert [c.split(":")[0] for c in checked] == ["simulate", "fit", "fit"]


def test_the_gap_filling_page_runs(folder):
    """Its inputs, as the page says: ``run/`` a fitted run and ``recording.csv`` its
    recording with gaps (here the triangle's true model, which made the recording: its fill
    is the recording)."""
    from activebonds import read_trajectory

    (folder / "run").mkdir()
    shutil.copy(ROOT / "examples" / "triangle.toml", folder / "run" / "best_model.toml")
    _recording_with_gaps(folder / "recording.csv")
    checked = run_page("howto/gap-filling.md", folder)
    assert checked == ["fill: 11 of 11 missing filled"] * 2
    truth = read_trajectory(ROOT / "examples" / "triangle.csv").positions
    gaps = ~read_trajectory("recording.csv").mask
    model = read_trajectory("filled.csv").positions[gaps] - truth[gaps]
    spline = read_trajectory("spline.csv").positions[gaps] - truth[gaps]
    assert np.abs(model).max() < 1e-5  # metres: the true model's fill is the recording
    assert np.abs(model).max() < np.abs(spline).max()


def test_the_tutorials_first_steps_run(folder):
    """The recording, a candidate model, the structure (the whole tutorial: slow)."""
    checked = run_page("tutorial.md", folder, stop=3)
    assert checked[0] == "info: 600 frames" and len(checked) == 3
    assert checked[1].startswith("scaffold: 7 particles") and checked[2].startswith("structure")


@pytest.mark.slow
def test_the_whole_tutorial_runs(folder):
    checked = run_page("tutorial.md", folder)
    kinds = [c.split(":")[0] for c in checked]
    assert kinds == ["info", "scaffold", "structure", "fit", "evaluate", "report", "fill", "python"]


@pytest.mark.slow
def test_the_auto_page_runs(folder):
    assert run_page("howto/auto.md", folder) == ["auto: every step's file"]


@pytest.mark.slow
def test_the_sweeps_page_runs(folder):
    assert run_page("howto/sweeps.md", folder) == ["sweep: 9 fits"]
