"""``activebonds sweep``: a manifest expanded and checked before anything runs, its fits run on
a local Ray cluster exactly as one after another without Ray, a worker killed mid-fit
(Ray's retry resumes the fit from its checkpoint to the same bits), and a rerun that skips
every finished fit."""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import psutil
import pytest
from typer.testing import CliRunner

from activebonds.atomic import staged_directory
from activebonds.cli.main import app
from activebonds.identify.rundir import RunDir
from activebonds.sweep import load_manifest
from helpers import ACTIVEBONDS, EXAMPLES

# 2 long fits (long enough for a worker to be killed between checkpoints), 10 short ones
MANIFEST = """
[defaults]
model = "triangle.toml"
data = "triangle.csv"
frames = "0:60"
population = 20
refine = "none"

[[fit]]
name = "long"
seed = [1, 2]
generations = 10000
checkpoint_every = 1000

[[fit]]
name = "short"
seed = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]
generations = 100
"""
NAMES = ["long-seed1", "long-seed2"] + [f"short-seed{s}" for s in range(1, 11)]


def _folder(tmp: Path) -> Path:
    shutil.copyfile(EXAMPLES / "triangle.toml", tmp / "triangle.toml")
    shutil.copyfile(EXAMPLES / "triangle.csv", tmp / "triangle.csv")
    (tmp / "sweep.toml").write_text(MANIFEST)
    return tmp


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    return _folder(tmp_path_factory.mktemp("sweep"))


def _start(*args, env: dict | None = None, log: Path) -> subprocess.Popen:
    """``activebonds ARGS`` in its own session (Ctrl-C reaches it and its Ray processes)."""
    env = dict(os.environ, COLUMNS="200", NO_COLOR="1", **(env or {}))
    with open(log, "wb") as out:
        return subprocess.Popen(
            [str(ACTIVEBONDS), *map(str, args)],
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )


def _finish(proc: subprocess.Popen, timeout: float = 240) -> int:
    """Wait for ``proc``; if it hangs, stop it as Ctrl-C would, then for good. Fails if any
    process it started (Ray's included) outlives it."""
    seen: dict[int, psutil.Process] = {}
    deadline = time.time() + timeout
    try:
        while proc.poll() is None:
            seen.update((p.pid, p) for p in _family(proc))
            if time.time() > deadline:
                os.killpg(proc.pid, signal.SIGINT)
                try:
                    proc.wait(timeout=60)
                except subprocess.TimeoutExpired:
                    os.killpg(proc.pid, signal.SIGKILL)
                raise AssertionError(f"still running after {timeout} s")
            time.sleep(0.2)
        return proc.returncode
    finally:
        _, alive = psutil.wait_procs(list(seen.values()), timeout=30)
        assert not alive, f"processes left behind: {[p.pid for p in alive]}"


def _family(proc: subprocess.Popen) -> list[psutil.Process]:
    try:
        return psutil.Process(proc.pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def _sweep(*args, env: dict | None = None, log: Path, timeout: float = 240) -> str:
    code = _finish(_start("sweep", *args, env=env, log=log), timeout)
    text = log.read_text()
    assert code == 0, text
    return text


def _result(run: Path) -> dict[str, bytes]:
    """What a fit decided: its history, best model and final state, as bytes."""
    found = {name: (run / name).read_bytes() for name in ("history.csv", "best_model.toml")}
    last = sorted((run / "checkpoints").glob("gen-*.npz"))[-1]
    with np.load(last) as z:
        found.update({f"{last.name}:{k}": z[k].tobytes() for k in z.files})
    return found


def _no_ray(folder: Path) -> dict:
    """An environment in which ``import ray`` fails, as if Ray were not installed."""
    hide = folder / "hide"
    (hide / "ray").mkdir(parents=True, exist_ok=True)
    (hide / "ray" / "__init__.py").write_text("raise ImportError('hidden by the test')\n")
    return {"PYTHONPATH": os.pathsep.join(filter(None, [str(hide), os.environ.get("PYTHONPATH")]))}


@pytest.fixture(scope="module")
def without_ray(inputs, tmp_path_factory) -> Path:
    """The 12 fits one after another in one process, Ray hidden as if not installed."""
    folder = tmp_path_factory.mktemp("no-ray")
    out = folder / "out"
    text = _sweep(inputs / "sweep.toml", "--out", out, env=_no_ray(inputs), log=folder / "log")
    assert text.count("Ray is not installed") == 1, text
    assert "12 fits: 12 run, 0 resumed, 0 skipped" in text, text
    return out


# ----------------------------------------------------------------------------- the manifest


def test_a_list_of_values_makes_one_fit_per_value(inputs):
    jobs = load_manifest(inputs / "sweep.toml")
    assert [j.name for j in jobs] == NAMES
    assert [j.settings.seed for j in jobs] == [1, 2, *range(1, 11)]
    assert {j.settings.population for j in jobs} == {20}
    assert jobs[0].settings.generations == 10000 and jobs[0].settings.checkpoint_every == 1000
    assert jobs[2].settings.generations == 100 and jobs[2].settings.checkpoint_every == 5000
    assert jobs[0].model == (inputs / "triangle.toml").resolve()
    assert jobs[0].settings.refine == "none"


def test_lists_of_lists_expand_and_list_settings_do_not(tmp_path):
    _folder(tmp_path)
    (tmp_path / "m.toml").write_text(
        """
        [[fit]]
        model = "triangle.toml"
        data = ["triangle.csv", "triangle.csv"]   # two recordings in one fit
        markers = ["A", "B", "C"]
        frames = ["0:40", [40, 80]]
        population = [8, 16]
        refine = "lm"
        horizon = [[1], [1, 4]]
        """
    )
    jobs = load_manifest(tmp_path / "m.toml")
    assert len(jobs) == 8
    assert len({j.name for j in jobs}) == 8
    assert jobs[0].name == "fit-1-frames0-40-population8-horizon1"
    assert jobs[-1].name == "fit-1-frames40-80-population16-horizon1-4"
    assert all(len(j.data) == 2 and j.settings.markers == ("A", "B", "C") for j in jobs)
    assert {j.settings.horizon for j in jobs} == {(1,), (1, 4)}
    assert {j.settings.frames for j in jobs} == {(0, 40), (40, 80)}


REFUSALS = {
    "missing file": ('data = "gone.csv"', "data", "no such file"),
    "bad model": ('model = "bad.toml"', "model", "particle[0].mas: unknown key"),
    "bad data": ('data = "bad.csv"', "data", "bad.csv"),
    "unknown key": ("populaton = 10", "populaton", "did you mean 'population'"),
    "bad value": ("population = [20, 2]", "population", "greater than or equal to 4"),
    "bad frames": ('frames = "0:2"', "frames", "at least 3 needed"),
    "unknown marker": ('markers = ["A", "B", "Z"]', "markers", "Z"),
    "duplicate names": ("seed = 0", "name", "also that of [[fit]] 1 (one)"),
}


@pytest.mark.parametrize("case", list(REFUSALS))
def test_a_bad_manifest_is_refused_in_one_line_before_anything_runs(tmp_path, case):
    _folder(tmp_path)
    (tmp_path / "bad.toml").write_text(
        'name = "x"\ndimension = 3\n[[particle]]\nname = "A"\nmas = 1\n'
    )
    (tmp_path / "bad.csv").write_text("not, a trajectory\n")
    line, field, expected = REFUSALS[case]
    name = "one" if case == "duplicate names" else "two"
    (tmp_path / "m.toml").write_text(
        f"""
        [defaults]
        model = "triangle.toml"
        data = "triangle.csv"

        [[fit]]
        name = "one"

        [[fit]]
        name = "{name}"
        {line}
        """
    )
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["sweep", str(tmp_path / "m.toml"), "--out", str(out)])
    assert res.exit_code == 2, res.output
    text = res.output.strip()
    assert len(text.splitlines()) == 1, text
    assert text.startswith(f"error: {tmp_path / 'm.toml'}: [[fit]] 2 ({name})"), text
    assert f"field {field}" in text and expected in text, text
    assert "Traceback" not in text
    assert not out.exists()


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_a_folder_of_other_runs_is_refused_before_anything_runs(without_ray, inputs, tmp_path):
    out = tmp_path / "out"
    shutil.copytree(without_ray / "short-seed1", out / "short-seed1")
    before = sorted(p.name for p in out.rglob("*"))
    (inputs / "other.toml").write_text(
        (inputs / "sweep.toml").read_text().replace("population = 20", "population = 30")
    )
    res = CliRunner().invoke(app, ["sweep", str(inputs / "other.toml"), "--out", str(out)])
    assert res.exit_code == 2, res.output
    assert "holds a run of other settings (population 20 -> 30)" in res.output
    assert sorted(p.name for p in out.rglob("*")) == before


# ----------------------------------------------------------------------------- running


@pytest.fixture(scope="module")
def on_ray(inputs, tmp_path_factory) -> dict:
    """The same 12 fits on a local Ray cluster of 2 workers; the worker that runs the first
    long fit killed (SIGKILL) once that fit has a checkpoint past generation 0."""
    folder = tmp_path_factory.mktemp("ray")
    out, log = folder / "out", folder / "log"
    started = time.time()
    proc = _start("sweep", inputs / "sweep.toml", "--out", out, "--workers", "2", log=log)
    try:
        run = out / "long-seed1"
        pid = _running_pid_after_a_checkpoint(run, out / ".running" / "long-seed1.pid")
        assert pid != proc.pid
        workers = {p.pid for p in _family(proc)}
        os.kill(pid, signal.SIGKILL)
    finally:
        code = _finish(proc)
    print(f"12 fits on Ray (2 workers, one killed): {time.time() - started:.1f} s")
    text = log.read_text()
    assert code == 0, text
    return {"out": out, "text": text, "killed": pid, "workers": workers}


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_twelve_fits_on_ray_match_the_fits_without_ray_bit_for_bit(on_ray, without_ray):
    out = on_ray["out"]
    assert "12 fits on a local Ray cluster of 2 workers" in on_ray["text"]
    for name in NAMES:
        assert _result(out / name) == _result(without_ray / name), name
    summary = (out / "summary.csv").read_text()
    assert summary == (without_ray / "summary.csv").read_text()
    rows = list(csv.DictReader(io.StringIO(summary)))
    assert list(rows[0])[:4] == ["name", "status", "seed", "generations"]
    assert "checkpoint_every" in rows[0]  # a setting that differs between the fits
    assert [r["name"] for r in rows] == NAMES
    assert [r["seed"] for r in rows] == ["1", "2", *map(str, range(1, 11))]
    assert {r["status"] for r in rows} == {"completed"}
    assert [r["generations"] for r in rows] == ["10000"] * 2 + ["100"] * 10
    for r in rows:  # each fit beats the zero-force baseline; every parameter identified
        assert float(r["rms_mm"]) < float(r["zero_force_rms_mm"])
        assert float(r["free_run_rms_mm"]) > 0 and float(r["frames_within_50mm"]) > 0
        assert 1 <= float(r["bond[2].stiffness"]) <= 1000
    page = (out / "summary.html").read_text()
    assert page.count("<tr>") == 13 and "short-seed10" in page and "<script" not in page
    assert not (out / ".running").exists()


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_a_killed_worker_is_retried_and_its_fit_ends_as_if_uninterrupted(on_ray, without_ray):
    assert on_ray["killed"] in on_ray["workers"]  # a process of the sweep's Ray cluster
    assert not psutil.pid_exists(on_ray["killed"])
    # the retried task found the checkpoint and resumed the fit
    assert "12 fits: 11 run, 1 resumed, 0 skipped" in on_ray["text"], on_ray["text"]
    run = on_ray["out"] / "long-seed1"
    assert _result(run) == _result(without_ray / "long-seed1")
    assert len(list((run / "checkpoints").glob("gen-*.npz"))) == 2


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_every_run_records_the_sweeps_command_line_not_its_workers(on_ray, inputs):
    out = on_ray["out"]
    expected = f"activebonds sweep {inputs / 'sweep.toml'} --out {out} --workers 2"
    for name in NAMES:
        assert json.loads((out / name / "run.json").read_text())["command"] == expected, name


def test_a_killed_create_leaves_staging_folders_that_remove_partial_removes(tmp_path):
    run = tmp_path / "fit-a"
    with pytest.raises(KeyboardInterrupt), staged_directory(run) as staging:
        (staging / "run.json").write_text("{}")
        kept = shutil.copytree(staging, tmp_path / f"{staging.name}-copy")  # as if killed
        raise KeyboardInterrupt
    others = [tmp_path / ".fit-b.partial-x", tmp_path / "fit-a.partial-x", tmp_path / "fit-b"]
    for folder in others:
        folder.mkdir()
    RunDir(run).remove_partial()
    assert not kept.exists() and not run.exists()
    assert all(folder.is_dir() for folder in others)


@pytest.mark.slow  # integration scale: in `pytest -m slow` (every landing)
def test_the_same_command_again_skips_every_finished_fit(inputs, without_ray, tmp_path):
    files = [p for p in without_ray.rglob("*") if p.is_file() and p.parent != without_ray]
    stamps = {p: p.stat().st_mtime_ns for p in files}
    args = (inputs / "sweep.toml", "--out", without_ray)
    text = _sweep(*args, env=_no_ray(inputs), log=tmp_path / "log")
    assert "12 fits: 0 run, 0 resumed, 12 skipped (finished before), 0 not completed" in text
    assert {p: p.stat().st_mtime_ns for p in files} == stamps
    assert len(stamps) > 12 * 5


def _running_pid_after_a_checkpoint(run: Path, pid_file: Path, timeout: float = 180) -> int:
    """The worker's process id, once ``run`` has a checkpoint past generation 0 and is not
    finished."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        later = [p for p in run.glob("checkpoints/gen-*.npz") if p.stem != "gen-000000000"]
        if later and pid_file.is_file():
            assert not (run / "status.json").read_text().count('"completed"')
            return int(pid_file.read_text().split()[0])
        time.sleep(0.05)
    raise AssertionError(f"no checkpoint of {run} within {timeout} s")
