"""Runs that never lose work to their output folder (issue 15, item 6).

* An output folder ``fit`` cannot write in (``--out`` under a file, an existing file, a
  read-only folder, a permission denied, a failing probe write): one line, exit 2, before any
  computation (the fit itself is never called), nothing left behind.
* Too little free space for what the run will write (checkpoints, history, the copies of the
  inputs): refused up front, one line, exit 2, no run directory; the same for ``resume``.
* A write that fails mid-run (ENOSPC injected into ``activebonds.atomic.write_atomic``, after
  part of the temporary file was written): the newest complete checkpoint is kept, one line
  names the file, the cause and that checkpoint, exit 1, no temporary file left; ``activebonds
  resume RUN`` then ends with the history and best model of an uninterrupted run, byte for
  byte. Cases: a checkpoint in the middle of the run, the history after a checkpoint, the
  final save of a finished fit, the first checkpoint (none kept yet), and the creation of the
  run directory itself (nothing kept, no run, no partial folder).

The fits run in this process through typer's test runner (the triangle's 30-frame recording,
population 12, 60 generations, a checkpoint every 20, no refinement).
"""

from __future__ import annotations

import errno
import os
import shutil
from collections import namedtuple
from pathlib import Path

import pytest
from typer.testing import CliRunner

import activebonds.atomic
import activebonds.identify
from activebonds.cli.main import app
from activebonds.identify.rundir import RunDir
from reliability_runner import ACTIVEBONDS, complete_checkpoints, env, leftovers, workspace

pytestmark = pytest.mark.timeout(600)

FIT = ("--population", "12", "--generations", "60", "--checkpoint-every", "20")
FIT += ("--seed", "2", "--refine", "none")


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "300"})


def error_line(res) -> str:
    lines = [line for line in res.stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, res.output
    assert "Traceback" not in res.output, res.output
    return lines[0]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    ws = workspace(tmp_path_factory)
    return ws["base"] / "triangle.toml", ws["base"] / "triangle.csv"


@pytest.fixture
def no_fit(monkeypatch):
    """The fit is never reached: calling it fails the test."""

    def fit(*args, **kwargs):
        raise AssertionError("the fit was called")

    monkeypatch.setattr(activebonds.identify, "fit", fit)


# ============================================================================ unwritable folders
def test_out_under_a_file_is_one_line_exit_2_through_the_command_line(tmp_path, inputs):
    """The real process: main(), exit code 2, stderr one line, nothing on stdout (the check
    comes before the inputs are even counted)."""
    import subprocess

    (tmp_path / "afile").write_text("mine")
    proc = subprocess.run(
        [str(ACTIVEBONDS), "fit", *inputs, "--out", str(tmp_path / "afile" / "RUN"), *FIT],
        env=env(None),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert (
        lines[0]
        == f"error: {tmp_path / 'afile' / 'RUN'}: {tmp_path / 'afile'} is a file, not a folder"
    )
    assert proc.stdout == ""
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


@pytest.mark.parametrize(
    "case",
    ["under-a-file", "deep-under-a-file", "an-existing-file", "a-file-with-overwrite", "no-parent"],
)
def test_an_output_folder_that_cannot_be_made_is_refused_before_the_fit(
    tmp_path, inputs, no_fit, case
):
    (tmp_path / "afile").write_text("mine")
    out, extra, said = {
        "under-a-file": (tmp_path / "afile" / "RUN", (), "is a file, not a folder"),
        "deep-under-a-file": (tmp_path / "afile" / "a" / "RUN", (), "is a file, not a folder"),
        "an-existing-file": (tmp_path / "afile", (), "already exists"),
        "a-file-with-overwrite": (tmp_path / "afile", ("--overwrite",), "not a run directory"),
        "no-parent": (tmp_path / "nope" / "RUN", (), "does not exist"),
    }[case]
    res = invoke("fit", *inputs, "--out", out, *FIT, *extra)
    assert res.exit_code == 2, res.output
    line = error_line(res)
    assert line.startswith(f"error: {out}: ") and said in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]
    assert (tmp_path / "afile").read_text() == "mine"


@pytest.mark.skipif(
    not hasattr(os, "geteuid") or os.geteuid() == 0,
    reason="root ignores permissions (the /sys and failing-probe cases cover it)",
)
def test_a_read_only_folder_is_refused_before_the_fit(tmp_path, inputs, no_fit):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o500)
    try:
        res = invoke("fit", *inputs, "--out", folder / "RUN", *FIT)
        assert res.exit_code == 2, res.output
        line = error_line(res)
        assert f"cannot write in {folder}" in line and "Permission denied" in line, line
        assert list(folder.iterdir()) == []
    finally:
        folder.chmod(0o700)


def _immutable(folder: Path, on: bool) -> bool:
    """``chattr +i`` / ``-i`` (Linux, root): a folder no one, root included, can write in."""
    import subprocess

    if shutil.which("chattr") is None:
        return False
    flag = "+i" if on else "-i"
    return subprocess.run(["chattr", flag, str(folder)], capture_output=True).returncode == 0


@pytest.mark.skipif(
    not hasattr(os, "geteuid") or os.geteuid() != 0, reason="chattr +i needs root (see chmod)"
)
def test_a_read_only_folder_is_refused_before_the_fit_even_as_root(tmp_path, inputs, no_fit):
    """Root ignores permissions, so the folder is made immutable instead (read-only for
    everyone): the probe is refused with EPERM, one line, exit 2, nothing written."""
    folder = tmp_path / "ro"
    folder.mkdir()
    if not _immutable(folder, True):
        pytest.skip("chattr +i is not allowed here")
    try:
        res = invoke("fit", *inputs, "--out", folder / "RUN", *FIT)
        assert res.exit_code == 2, res.output
        line = error_line(res)
        assert f"cannot write in {folder}" in line and "Operation not permitted" in line, line
        assert list(folder.iterdir()) == []
    finally:
        _immutable(folder, False)


@pytest.mark.skipif(not Path("/sys/kernel").is_dir(), reason="Linux's sysfs")
def test_a_folder_where_even_root_cannot_create_files_is_refused(tmp_path, inputs, no_fit):
    """sysfs takes no new file from anyone, root included: the probe write is refused."""
    out = Path("/sys") / f"activebonds-test-{os.getpid()}"
    res = invoke("fit", *inputs, "--out", out, *FIT)
    assert res.exit_code == 2, res.output
    line = error_line(res)
    assert "cannot write in /sys" in line, line
    assert not out.exists()


@pytest.mark.parametrize("where", ["create", "write"])
def test_a_failing_probe_is_one_line(tmp_path, inputs, no_fit, monkeypatch, where):
    """Permission denied creating the probe, or no space writing it (root-proof: injected)."""
    import tempfile

    if where == "create":

        def mkstemp(*args, **kwargs):
            raise PermissionError(errno.EACCES, "Permission denied", str(tmp_path / ".RUN.probe"))

        monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    else:
        real = os.write

        def write(fd, data):
            if data == b"probe":
                raise OSError(errno.ENOSPC, "No space left on device")
            return real(fd, data)

        monkeypatch.setattr(os, "write", write)
    res = invoke("fit", *inputs, "--out", tmp_path / "RUN", *FIT)
    assert res.exit_code == 2, res.output
    line = error_line(res)
    cause = "Permission denied" if where == "create" else "No space left on device"
    assert f"cannot write in {tmp_path} ({cause})" in line, line
    assert list(tmp_path.iterdir()) == []


# ============================================================================ free space
Usage = namedtuple("Usage", "total used free")


def test_too_little_free_space_is_refused_up_front(tmp_path, inputs, monkeypatch):
    monkeypatch.setattr(shutil, "disk_usage", lambda path: Usage(10**9, 10**9 - 20_000, 20_000))
    res = invoke("fit", *inputs, "--out", tmp_path / "RUN", *FIT)
    assert res.exit_code == 2, res.output
    line = error_line(res)
    assert "not enough free space: the run writes about" in line and "0.02 MB free" in line, line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_the_space_estimate_covers_what_a_run_writes(tmp_path, inputs):
    """The estimate is an upper bound of what a finished run holds (so a refusal is never of a
    run that would fit), within a factor that keeps it meaningful."""
    from activebonds.identify import FitSettings, fit

    settings = FitSettings(population=12, generations=60, checkpoint_every=20, refine="none")
    result = fit(*inputs, settings, out=tmp_path / "RUN")
    meta = RunDir(result.run).meta()
    shapes = RunDir.state_shapes(_template(result))
    need = RunDir.expected_bytes(
        RunDir.state_bytes(shapes), len(meta["history"]["columns"]), settings.generations
    )
    held = RunDir(result.run).used_bytes()
    assert held < need < 40 * held, (held, need)


def _template(result):
    from activebonds.identify import driver
    from activebonds.identify.search import strategies
    from activebonds.identify.search.evolve import Evolution, keys

    ident, s = result.identification, result.settings
    strategy = strategies.make(s.optimizer, ident.problem, s, driver._dtype(s))
    display = driver.Display(ident.windows.n_terms)
    loop = Evolution(strategy, ident.problem, driver._dtype(s), total=60, display=display)
    return loop.template(keys(s.seed)[0])


# ============================================================================ ENOSPC mid-run
def fail_write(monkeypatch, matches):
    """``activebonds.atomic.write_atomic`` writes half of the file whose path ``matches(path,
    count)`` (count: how many writes of that file name came before), then raises ENOSPC."""
    real = activebonds.atomic.write_atomic
    seen: dict[str, int] = {}
    failed = []

    def write_atomic(path, write):
        path = Path(path)
        count = seen.get(path.name, 0)
        seen[path.name] = count + 1
        if failed or not matches(path, count):
            return real(path, write)

        def half(fh):
            import io

            buf = io.BytesIO()
            write(buf)
            fh.write(buf.getvalue()[: len(buf.getvalue()) // 2])
            failed.append(path)
            raise OSError(errno.ENOSPC, "No space left on device")

        return real(path, half)

    monkeypatch.setattr(activebonds.atomic, "write_atomic", write_atomic)
    return failed


@pytest.fixture(scope="module")
def uninterrupted(inputs, tmp_path_factory):
    run = tmp_path_factory.mktemp("ref") / "RUN"
    res = invoke("fit", *inputs, "--out", run, *FIT)
    assert res.exit_code == 0, res.output
    return run


CASES = {
    # a checkpoint in the middle of the run: the one before it is kept
    "checkpoint-40": (lambda p, n: p.name == "gen-000000040.npz", 20),
    # history.csv after the checkpoint of generation 20 was written
    "history-after-20": (lambda p, n: p.name == "history.csv" and n == 1, 20),
    # the final save of a finished fit
    "final-checkpoint": (lambda p, n: p.name == "gen-000000060.npz", 40),
    # the very first checkpoint: nothing kept yet, resume starts afresh
    "first-checkpoint": (lambda p, n: p.name == "gen-000000000.npz", None),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_full_disk_mid_run_keeps_the_checkpoint_and_resume_finishes_the_job(
    tmp_path, inputs, uninterrupted, monkeypatch, case
):
    matches, kept = CASES[case]
    run = tmp_path / "RUN"
    failed = fail_write(monkeypatch, matches)
    res = invoke("fit", *inputs, "--out", run, *FIT)
    assert res.exit_code == 1, res.output
    line = error_line(res)
    assert len(failed) == 1, failed
    assert line.startswith(f"error: could not write {failed[0]}: No space left on device; "), line
    if kept is None:
        assert "no checkpoint was written yet" in line, line
        assert f"`activebonds resume {run}` starts the run again" in line, line
        assert complete_checkpoints(run) == []
    else:
        assert f"the checkpoint at generation {kept} is kept" in line, line
        assert line.endswith(f"free some space, then `activebonds resume {run}`"), line
        assert max(complete_checkpoints(run)) == kept
    assert leftovers(run) == []  # the half-written temporary file is gone

    monkeypatch.undo()  # space again
    resumed = invoke("resume", run)
    assert resumed.exit_code == 0, resumed.output
    for name in ("history.csv", "best_model.toml"):
        assert (run / name).read_bytes() == (uninterrupted / name).read_bytes(), name


def test_a_full_disk_while_creating_the_run_leaves_nothing(tmp_path, inputs, monkeypatch):
    real = Path.write_bytes

    def write_bytes(self, data):
        if self.name == "data.npz":
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, data)

    monkeypatch.setattr(Path, "write_bytes", write_bytes)
    run = tmp_path / "RUN"
    res = invoke("fit", *inputs, "--out", run, *FIT)
    assert res.exit_code == 1, res.output
    line = error_line(res)
    assert line == (
        f"error: could not write {run}: No space left on device; nothing was kept: free some "
        "space (or choose another --out), then fit again"
    )
    assert list(tmp_path.iterdir()) == []


def test_resume_refuses_too_little_space_and_changes_nothing(tmp_path, uninterrupted, monkeypatch):
    run = shutil.copytree(uninterrupted, tmp_path / "RUN")
    RunDir(run).write_status(**{**RunDir(run).status(), "status": "interrupted"})
    (run / "checkpoints" / "gen-000000060.npz").unlink()  # back to generation 40
    before = {p.name: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    monkeypatch.setattr(shutil, "disk_usage", lambda path: Usage(10**9, 10**9, 0))
    res = invoke("resume", run)
    assert res.exit_code == 2, res.output
    line = error_line(res)
    assert line.startswith(f"error: {run}: not enough free space: resuming writes about"), line
    assert {p.name: p.read_bytes() for p in run.rglob("*") if p.is_file()} == before
