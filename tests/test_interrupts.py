"""Ctrl-C at any moment of ``activebonds fit``: a clean end and a true message.

``activebonds fit`` of the triangle (its 30-frame simulated recording, population 10, 2000
generations) runs in a subprocess without the compilation cache (``ACTIVEBONDS_CACHE=off``, so
it really compiles); SIGINT is sent at staggered moments that span the whole start: right after
the command line installed its handler (imports, reading, identification), right after the run
directory appeared (the start's compilation), after the first checkpoint (the chunk's
compilation, the first generations), later (refinement, uncertainty, summary), and twice in a
row (the second Ctrl-C stops at once). Tries run two at a time.

For every try: no negative return code (no segfault, no death by the signal), exit 130 or 0,
no traceback or "Exception ignored" on stderr, and a true message:

* "interrupted before the run started; nothing was written": the try's folder is empty (no
  RUN, no hidden partial folder, no probe file);
* "interrupted; continue with: activebonds resume RUN": RUN exists and ``resume`` accepts it
  (its run.json reads, its inputs are unchanged, every checkpoint file in it is complete);
  with ``-m slow`` one such run is resumed through the command line to its end;
* "interrupted after the fit completed; its results are in RUN", or exit 0: the run completed.

The default run has 20 tries, ``-m slow`` 26 and one resume to the end (116 s).
``python tests/test_interrupts.py [SRC]`` runs the 26 against any package source: on the
package before the fix (commit 82bdae9) 8 of 26 died by a signal (6 segmentation faults), 5
lost the Ctrl-C in JAX's gc callback and went on to exit 0, 18 had a problem; after, none
(docs/RELIABILITY.md, section 8).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from activebonds.identify.rundir import RunDir
from reliability_runner import ACTIVEBONDS, complete_checkpoints, env, workspace

pytestmark = pytest.mark.timeout(600)

FIT = ("--population", "10", "--generations", "2000", "--seed", "1")

# (trigger, seconds after it): "ready" = the process has its second thread (the command line's
# SIGINT watcher, the first thread it starts), "run" = RUN exists, "gen0" = RUN's first
# checkpoint exists, "end" = the ES's last checkpoint exists (refinement, uncertainty and
# summary follow); "twice" sends a second SIGINT 0.3 s after the first.
# The default run: 6 tries, one or two per moment and one doubled SIGINT, most of them landing in
# the compilations (start-up, the start's population, the first chunk), where the
# segmentation faults were.
DEFAULT_TRIES = (
    [("ready", 0.0), ("ready", 0.8), ("run", 0.1), ("gen0", 0.7)]
    + [("ready", 0.5, "twice")]
    + [("end", 0.3)]
)
SLOW_TRIES = (
    [("ready", d) for d in (0.0, 0.15, 0.3, 0.5, 0.8, 1.2, 1.8)]
    + [("run", d) for d in (0.0, 0.1, 0.25, 0.5, 0.8)]
    + [("gen0", d) for d in (0.0, 0.3, 0.7, 1.2, 2.0, 3.0, 4.5)]
    + [("ready", 0.5, "twice"), ("run", 0.1, "twice"), ("gen0", 0.5, "twice")]
    + [("end", d) for d in (0.0, 0.5, 1.5, 3.0)]
)
LAST = "gen-000002000.npz"


def _threads(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("Threads:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return 0


def _reached(trigger: str, proc, run: Path) -> bool:
    if trigger == "ready":
        if not Path("/proc/self/status").exists():  # not Linux: give start-up half a second
            return time.monotonic() - proc.started > 0.5
        return _threads(proc.pid) >= 2
    if trigger == "run":
        return run.is_dir()
    name = LAST if trigger == "end" else "gen-000000000.npz"
    return (run / "checkpoints" / name).is_file()


def run_tries(command: list[str], data: Path, model: Path, base: Path, tries, extra_env=None):
    """Each try a fit in its own folder base/tryN/RUN, interrupted as the try says; two at a
    time. Returns [(try, folder, CompletedProcess, sent)] (``sent``: SIGINTs sent)."""
    environment = dict(env(None), ACTIVEBONDS_CACHE="off", **(extra_env or {}))
    results = []
    for start in range(0, len(tries), 2):
        batch = []
        for i in range(start, min(start + 2, len(tries))):
            folder = base / f"try{i}"
            folder.mkdir()
            argv = [*command, "fit", str(model), str(data), "--out", str(folder / "RUN"), *FIT]
            proc = subprocess.Popen(
                argv,
                cwd=folder,
                env=environment,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            proc.started = time.monotonic()
            batch.append({"try": tries[i], "folder": folder, "proc": proc, "at": None, "sent": 0})
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and any(b["proc"].poll() is None for b in batch):
            now = time.monotonic()
            for b in batch:
                trigger, delay, *twice = b["try"]
                if b["proc"].poll() is not None:
                    continue
                if b["at"] is None and _reached(trigger, b["proc"], b["folder"] / "RUN"):
                    b["at"] = now + delay
                limit = 2 if twice else 1
                if b["at"] is not None and b["sent"] < limit and now >= b["at"]:
                    b["proc"].send_signal(signal.SIGINT)
                    b["sent"] += 1
                    b["at"] = now + 0.3
            time.sleep(0.005)
        for b in batch:
            try:
                out, err = b["proc"].communicate(timeout=60)
            except subprocess.TimeoutExpired:
                b["proc"].kill()
                out, err = b["proc"].communicate()
            done = subprocess.CompletedProcess(b["proc"].args, b["proc"].returncode, out, err)
            results.append((b["try"], b["folder"], done, b["sent"]))
    return results


def problems_of(results) -> tuple[list[str], dict]:
    """What is wrong with each try (an empty list: nothing), and the counts of outcomes."""
    problems, counts = [], {}
    for spec, folder, proc, sent in results:
        run = folder / "RUN"
        err = proc.stderr
        lines = [line for line in err.splitlines() if line.startswith("error:")]
        last = lines[-1] if lines else ""
        story = f"try {spec} (sent {sent}): exit {proc.returncode}, stderr {err!r}"
        if proc.returncode < 0:
            problems.append(f"{story}: killed by signal {-proc.returncode}")
            counts["negative"] = counts.get("negative", 0) + 1
            continue
        if proc.returncode not in (0, 130):
            problems.append(f"{story}: exit code")
        if "Traceback" in err or "Exception ignored" in err:
            problems.append(f"{story}: a traceback")
        if proc.returncode == 0:
            kind = "completed"
            status = json.loads((run / "status.json").read_text())
            if status.get("status") != "completed":
                problems.append(f"{story}: exit 0 but status {status}")
        elif "nothing was written" in last:
            kind = "before the run"
            left = sorted(p.name for p in folder.iterdir())
            if left:
                problems.append(f"{story}: says nothing was written, left {left}")
        elif f"continue with: activebonds resume {run}" in last:
            kind = "resume"
            problems += [f"{story}: {p}" for p in resume_refusals(run)]
        elif "after the fit completed" in last:
            kind = "after the fit"
            status = json.loads((run / "status.json").read_text())
            if status.get("status") != "completed" or not (run / "best_model.toml").is_file():
                problems.append(f"{story}: says completed, status {status}")
        else:
            kind = "other"
            problems.append(f"{story}: no true message")
        counts[kind] = counts.get(kind, 0) + 1
    return problems, counts


def resume_refusals(run: Path) -> list[str]:
    """Why ``activebonds resume RUN`` would refuse RUN (empty: it accepts it), without
    compiling anything: what it reads and checks before it evolves."""
    if not run.is_dir():
        return ["no run directory"]
    try:
        meta = RunDir(run).meta()
        RunDir(run).check_unchanged(meta)
        RunDir(run).windows()
        RunDir(run).input_model()
    except Exception as err:  # noqa: BLE001 - any refusal is the finding
        return [f"resume refuses it: {err}"]
    files = sorted((run / "checkpoints").glob("gen-*.npz"))
    if len(complete_checkpoints(run)) != len(files):
        return [f"an incomplete checkpoint among {[p.name for p in files]}"]
    return []


def _check(tries, tmp_path, tmp_path_factory, resume: bool):
    ws = workspace(tmp_path_factory)
    started = time.monotonic()
    results = run_tries(
        [str(ACTIVEBONDS)],
        ws["base"] / "triangle.csv",
        ws["base"] / "triangle.toml",
        tmp_path,
        tries,
    )
    problems, counts = problems_of(results)
    print(f"{len(results)} tries in {time.monotonic() - started:.0f} s: {counts}")
    assert not problems, "\n".join(problems)
    # one interrupted run is resumed through the command line, to its end
    advised = [f / "RUN" for _, f, p, _ in results if "continue with" in p.stderr]
    if resume and advised:
        proc = subprocess.run(
            [str(ACTIVEBONDS), "resume", str(advised[0])],
            env=dict(env(None), ACTIVEBONDS_CACHE="off"),
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert proc.returncode == 0, proc.stderr
        assert json.loads((advised[0] / "status.json").read_text())["status"] == "completed"
    return counts


@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT to a child process is POSIX")
@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_ctrl_c_at_staggered_moments_ends_cleanly_with_a_true_message(tmp_path, tmp_path_factory):
    counts = _check(DEFAULT_TRIES, tmp_path, tmp_path_factory, resume=False)
    assert counts.get("before the run", 0) >= 1 and counts.get("resume", 0) >= 1, counts


@pytest.mark.slow
@pytest.mark.skipif(sys.platform == "win32", reason="SIGINT to a child process is POSIX")
def test_ctrl_c_at_staggered_moments_26_tries(tmp_path, tmp_path_factory):
    counts = _check(SLOW_TRIES, tmp_path, tmp_path_factory, resume=True)
    assert counts.get("before the run", 0) >= 3 and counts.get("resume", 0) >= 3, counts


def test_an_interrupt_acted_on_in_process_says_resume_only_for_a_run(tmp_path, monkeypatch):
    """In a process that imports the package (here, through typer's test runner), Python's own
    KeyboardInterrupt: before the run directory exists the message says nothing was written;
    with it, it advises resume."""
    from typer.testing import CliRunner

    import activebonds.identify
    from activebonds.cli.main import app

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(activebonds.identify, "fit", interrupted)
    ex = Path(__file__).resolve().parents[1] / "src" / "activebonds" / "examples"
    data = tmp_path / "tri.csv"
    from activebonds.data import write_trajectory
    from activebonds.model import load_model
    from activebonds.simulation import simulate

    write_trajectory(simulate(load_model(ex / "triangle.toml"), n_frames=30, rate=60.0), data)
    run = tmp_path / "R"
    before = signal.getsignal(signal.SIGINT)  # Python's own, or SIG_IGN in a background job
    res = CliRunner().invoke(app, ["fit", str(ex / "triangle.toml"), str(data), "--out", str(run)])
    assert res.exit_code == 130
    assert res.stderr.strip().endswith("interrupted before the run started; nothing was written")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tri.csv"]
    assert signal.getsignal(signal.SIGINT) is before  # left as it was


def _noisy_triangle():
    from activebonds.data import Trajectory
    from activebonds.model import load_model
    from activebonds.simulation import simulate

    ex = Path(__file__).resolve().parents[1] / "src" / "activebonds" / "examples"
    rec = simulate(load_model(ex / "triangle.toml"), 100, 100.0)
    noise = np.random.default_rng(0).normal(0.0, 5e-4, rec.positions.shape)
    return ex / "triangle.toml", Trajectory(rec.positions + noise, rec.mask, rec.markers, rec.rate)


class _Flag:
    """A simulated Ctrl-C: the stop check says yes from its ``after``-th poll on."""

    def __init__(self, after: int):
        self.after, self.polls = after, 0

    def __call__(self) -> bool:
        self.polls += 1
        return self.polls >= self.after


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_ctrl_c_during_the_refinement_stops_within_one_step_and_resumes(tmp_path):
    """The refinement's Levenberg-Marquardt loop polls for a Ctrl-C between two steps (the
    command line registers its guard's flag, here a simulated one): the first poll that says
    yes ends the fit (a KeyboardInterrupt), the stage saved where it got to, the run's status
    "interrupted"; ``resume`` continues that stage and ends where an uninterrupted fit ends
    (multiple shooting, converged: the same genome)."""
    from activebonds import runtime
    from activebonds.identify import fit, resume
    from activebonds.identify.solvers.refine import StageInterrupted

    model, data = _noisy_triangle()
    options = dict(population=8, generations=2, cost="shooting", horizon=(10,))
    flag = _Flag(after=4)  # the driver's poll before the refinement stage, then its steps
    runtime.on_stop_request(flag)
    try:
        with pytest.raises(StageInterrupted) as stopped:
            fit(model, data, out=tmp_path / "R", **options)
    finally:
        runtime.on_stop_request(None)
    assert isinstance(stopped.value, KeyboardInterrupt)
    assert flag.polls == 4  # no step after the poll that said stop
    record = json.loads((tmp_path / "R" / "refine.json").read_text())
    assert record["stages"] == []
    partial = record["interrupted"]
    assert (partial["horizon"], partial["cost"], partial["steps"]) == (10, "shooting", 3)
    assert partial["message"] == "interrupted after 3 steps (Ctrl-C); resume continues from here"
    assert len(partial["genome"]) == 9
    assert RunDir(tmp_path / "R").status()["status"] == "interrupted"
    resumed = resume(tmp_path / "R")
    (stage,) = resumed.records["refine"]["stages"]
    assert stage["message"].startswith("continued after an interrupt at step 3: converged")
    assert "interrupted" not in json.loads((tmp_path / "R" / "refine.json").read_text())
    straight = fit(model, data, out=tmp_path / "S", **options)
    assert np.allclose(resumed.genome, straight.genome, rtol=0, atol=1e-9)


def test_the_command_line_says_resume_after_a_ctrl_c_in_the_refinement(tmp_path):
    """The same simulated Ctrl-C through ``activebonds fit`` (in-process): exit 130, one
    line advising resume, the run resumable."""
    from typer.testing import CliRunner

    from activebonds import runtime
    from activebonds.cli.main import app
    from activebonds.data import write_trajectory

    model, data = _noisy_triangle()
    write_trajectory(data, tmp_path / "tri.csv")
    run = tmp_path / "R"
    argv = ["fit", str(model), str(tmp_path / "tri.csv"), "--out", str(run)]
    argv += ["--population", "8", "--generations", "2", "--cost", "shooting", "--horizon", "10"]
    runtime.on_stop_request(_Flag(after=3))  # the driver's poll before the stage, 2 steps
    try:
        res = CliRunner().invoke(app, argv)
    finally:
        runtime.on_stop_request(None)
    assert res.exit_code == 130, res.output
    assert (
        res.stderr.strip().splitlines()[-1]
        == f"error: interrupted; continue with: activebonds resume {run}"
    )
    assert json.loads((run / "refine.json").read_text())["interrupted"]["steps"] == 2


def main(argv: list[str]) -> int:
    """``python tests/test_interrupts.py [SRC] [N]``: the first N (default 26) tries of the slow
    test against the package in SRC (default: this checkout; e.g. an older commit extracted with
    ``git archive COMMIT src | tar -x -C DIR``, then SRC=DIR/src), through ``python -m
    activebonds.cli`` with ``PYTHONPATH=SRC``. Prints each try's exit code and last line, and
    the counts (how many died by a signal)."""
    import shutil
    import tempfile

    from activebonds.data import write_trajectory
    from activebonds.model import load_model
    from activebonds.simulation import simulate

    root = Path(__file__).resolve().parents[1]
    src = Path(argv[0]).resolve() if argv else root / "src"
    n = int(argv[1]) if len(argv) > 1 else len(SLOW_TRIES)
    base = Path(tempfile.mkdtemp(prefix="activebonds-interrupts-"))
    examples = root / "src" / "activebonds" / "examples"
    shutil.copyfile(examples / "triangle.toml", base / "triangle.toml")
    recording = simulate(load_model(examples / "triangle.toml"), n_frames=30, rate=60.0)
    write_trajectory(recording, base / "triangle.csv")
    (base / "tries").mkdir()
    started = time.monotonic()
    results = run_tries(
        [sys.executable, "-m", "activebonds.cli"],
        base / "triangle.csv",
        base / "triangle.toml",
        base / "tries",
        SLOW_TRIES[:n],
        extra_env={"PYTHONPATH": str(src)},
    )
    problems, counts = problems_of(results)
    for spec, _, proc, sent in results:
        last = [line for line in proc.stderr.splitlines() if line.strip()][-1:]
        print(spec, f"sent {sent}", f"exit {proc.returncode}", last)
    negative = sum(proc.returncode < 0 for _, _, proc, _ in results)
    print(f"{len(results)} tries in {time.monotonic() - started:.0f} s: {counts}")
    print(f"died by a signal: {negative}; with a problem: {len(problems)}")
    shutil.rmtree(base, ignore_errors=True)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
