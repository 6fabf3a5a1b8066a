"""``activebonds auto`` over a dataset on a Ray cluster that is a cluster: a head node and a
worker node, each started by ``ray start`` as a process group of its own on this machine; the
dataset run with ``--address``; the worker node killed (every process of it, SIGKILL) while it
runs a trial. Every trial finishes (Ray retries the lost task on the head, where it resumes
from the trial's folder) with the numbers of the same dataset run on this machine alone; and
the driver killed with ``kill -9`` mid-dataset, the same command run again finishes with
those numbers too."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from test_auto_dataset import _numbers, _rows, make_trials

ARGS = ["--no-gravity", "--population", "8", "--generations", "5", "--ahead", "5"]
BIN = Path(sys.executable).parent


def _auto(paths, out: Path, *extra: str, wait: bool = True, env=None):
    cmd = [sys.executable, "-m", "activebonds.cli", "auto", *map(str, paths), "--out", str(out)]
    proc = subprocess.Popen(
        [*cmd, *ARGS, *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env
    )
    if wait:
        stdout, stderr = proc.communicate(timeout=900)
        assert proc.returncode == 0, stderr[-3000:]
        return stdout
    return proc


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _running(out: Path) -> dict[str, int]:
    """trial -> the process id of the worker running it (``OUT/.running/TRIAL.pid``)."""
    found = {}
    for mark in (out / ".running").glob("*.pid") if (out / ".running").is_dir() else []:
        try:
            found[mark.stem] = int(mark.read_text().split()[0])
        except (OSError, ValueError, IndexError):
            pass
    return found


def _session_of(pid: int) -> int | None:
    try:
        return os.getsid(pid)
    except (ProcessLookupError, PermissionError):
        return None


def _kill_session(sid: int) -> int:
    """SIGKILL to every process of session ``sid`` (a node: ``ray start``, its raylet and
    the workers the raylet started, each of those in a process group of its own); how many."""
    killed = 0
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and _session_of(int(entry.name)) == sid:
            try:
                os.kill(int(entry.name), signal.SIGKILL)
                killed += 1
            except ProcessLookupError:
                pass
    return killed


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_a_worker_node_killed_mid_run_every_trial_finishes_with_the_local_numbers(tmp_path):
    pytest.importorskip("ray")
    paths = make_trials(tmp_path / "data")[:3]
    _auto(paths, tmp_path / "local", "--sequential")
    local = _numbers(_rows(tmp_path / "local"))
    assert [r[1] for r in local] == ["done"] * 3

    port = _free_port()
    temp = Path("/tmp") / f"ab-ray-{os.getpid()}"  # short: Ray's socket paths are limited
    ray = str(BIN / "ray")
    # Ray >= 2.59 turns token authentication on for a head started where a token file exists
    # (an earlier local cluster's), which a client it does not configure cannot pass: off here
    env = dict(os.environ, RAY_USAGE_STATS_ENABLED="0", RAY_AUTH_MODE="disabled")
    head_args = ["--head", f"--port={port}", "--num-cpus=1", "--include-dashboard=false"]
    head = subprocess.Popen(
        [ray, "start", *head_args, f"--temp-dir={temp}", "--block"],
        start_new_session=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    worker = None
    try:
        time.sleep(8)
        worker = subprocess.Popen(
            [ray, "start", f"--address=127.0.0.1:{port}", "--num-cpus=1", "--block"],
            start_new_session=True, env=env, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )  # fmt: skip
        time.sleep(8)
        out = tmp_path / "cluster"
        driver = _auto(paths, out, "--address", f"127.0.0.1:{port}", wait=False, env=env)
        killed = None
        deadline = time.time() + 300
        while killed is None and time.time() < deadline and driver.poll() is None:
            for trial, pid in _running(out).items():
                if _session_of(pid) == worker.pid:  # a trial running on the worker node
                    assert _kill_session(worker.pid) >= 3  # ray start, raylet, the worker
                    killed = trial
                    break
            time.sleep(0.2)
        stdout, stderr = driver.communicate(timeout=900)
        assert killed is not None, "no trial ran on the worker node"
        assert driver.returncode == 0, stderr[-3000:]
        assert _numbers(_rows(out)) == local
    finally:
        for proc in (worker, head):
            if proc is not None:
                _kill_session(proc.pid)
                proc.wait()
        # not `ray stop`: it would stop every Ray cluster of the machine (another test's)


@pytest.mark.slow  # integration scale: in pytest -m slow (every landing)
def test_the_driver_killed_mid_dataset_the_same_command_finishes_with_the_same_numbers(tmp_path):
    paths = make_trials(tmp_path / "data")[:2]
    _auto(paths, tmp_path / "whole", "--sequential")
    whole = _numbers(_rows(tmp_path / "whole"))
    out = tmp_path / "killed"
    driver = _auto(paths, out, "--sequential", wait=False)
    deadline = time.time() + 300
    while time.time() < deadline and not (out / "early" / "run").is_dir():
        time.sleep(0.1)
    time.sleep(1.0)
    driver.send_signal(signal.SIGKILL)
    driver.communicate()  # its pipes read and closed
    assert not (out / "summary.csv").exists() or len(_rows(out)) < 2  # killed before the end
    _auto(paths, out, "--sequential")
    assert _numbers(_rows(out)) == whole
