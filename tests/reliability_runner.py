"""A tiny fit runner and shared helpers for the reliability tests (not a test module).

As a script, it runs :func:`activebonds.identify.fit` (or ``resume``) with a run directory:
``activebonds fit`` does not expose ``FitSettings.chunk`` and the kill/resume tests need
small chunks so that checkpoints land every ``--checkpoint-every`` generations. It prints
``gen N`` (flushed) after every chunk, so a test knows how far the run got when it killed it.
``--throttle`` sleeps that many seconds per chunk: it slows the run down without changing
any result, so kills at random moments land inside the evolution rather than in start-up.

    python tests/reliability_runner.py fit MODEL DATA OUT --seed 3 --population 30 \
        --generations 400 --checkpoint-every 50 --chunk 10 [--bonds neural] [--frames 0:30] \
        [--optimizer random]
    python tests/reliability_runner.py resume OUT [--throttle 0.02]

As a module, it gives the tests their shared pieces: the small problems, a workspace with
copies of the inputs, memoised reference runs (one per pytest process), the command line in
a subprocess, a persistent JAX compilation cache for those subprocesses (compiling the ES
is most of a small fit's time; the cache changes no result, see test_reliability_resume's
determinism test, which runs without it), and readers of run directories.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "src" / "activebonds" / "examples"
HORSE_TROT = (
    ROOT / "src" / "activebonds" / "datasets" / "horse_vhdc" / "Horse1_M1_trot1_kinematics.csv"
)
ACTIVEBONDS = Path(sys.executable).with_name("activebonds")
RUNNER = Path(__file__).resolve()

# The kill/resume problem: population 30, 400 generations, a checkpoint every 50, chunks of 10.
FIT = {"seed": 3, "population": 30, "generations": 400, "checkpoint_every": 50, "chunk": 10}
PROBLEMS = {
    # examples/triangle.toml on its own 30-frame simulated trajectory (60 Hz)
    "triangle": {"model": "triangle.toml", "data": "triangle.csv", "extra": []},
    # the horse: 3 markers (Head, Withers, HFL), neural bonds, the first 30 frames of the trot
    "horse": {
        "model": "horse_limb.toml",
        "data": "horse_trot.csv",
        "extra": ["--bonds", "neural", "--frames", "0:30"],
    },
}


# ----------------------------------------------------------------------------- the script
def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser()
    sub = p.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fit")
    f.add_argument("model")
    f.add_argument("data")
    f.add_argument("out")
    f.add_argument("--seed", type=int, default=FIT["seed"])
    f.add_argument("--population", type=int, default=FIT["population"])
    f.add_argument("--generations", type=int, default=FIT["generations"])
    f.add_argument("--checkpoint-every", type=int, default=FIT["checkpoint_every"])
    f.add_argument("--chunk", type=int, default=FIT["chunk"])
    f.add_argument("--bonds", default="model")
    f.add_argument("--frames", default="0:")
    f.add_argument("--horizon", type=int, default=1)
    f.add_argument("--optimizer", default="es")
    f.add_argument("--throttle", type=float, default=0.0)
    r = sub.add_parser("resume")
    r.add_argument("out")
    r.add_argument("--throttle", type=float, default=0.0)
    a = p.parse_args(argv)

    from activebonds.errors import InputError
    from activebonds.identify import FitSettings, fit, resume
    from activebonds.identify.settings import parse_frames

    def progress(gen: int, total: int, rms: float) -> None:
        print(f"gen {gen}", flush=True)
        if a.throttle:
            time.sleep(a.throttle)

    try:
        if a.cmd == "resume":
            result = resume(a.out, progress=progress)
        else:
            settings = FitSettings(
                seed=a.seed,
                population=a.population,
                generations=a.generations,
                checkpoint_every=a.checkpoint_every,
                chunk=a.chunk,
                bonds=a.bonds,
                frames=parse_frames(a.frames),
                horizon=a.horizon,
                optimizer=a.optimizer,
                refine="none",  # the ES alone: the kill/resume problem is the evolution's
            )
            result = fit(a.model, a.data, settings, out=a.out, progress=progress)
    except InputError as e:
        print(f"error: {e.line()}", file=sys.stderr)
        return 2
    print(f"done {result.status}", flush=True)
    return 0 if result.status == "completed" else 1


# ----------------------------------------------------------------------------- subprocesses
def env(cache: Path | None = None) -> dict:
    """Environment of a subprocess: plain output; with ``cache``, JAX's persistent
    compilation cache in that folder (every compilation cached)."""
    e = dict(os.environ, COLUMNS="200", NO_COLOR="1", TERM="dumb")
    for k in list(e):
        if k.startswith("JAX_COMPILATION_CACHE") or k.startswith("JAX_PERSISTENT_CACHE"):
            del e[k]
    if cache is not None:
        e["JAX_COMPILATION_CACHE_DIR"] = str(cache)
        e["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
        e["JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES"] = "0"
    return e


def cli(*args, cache: Path | None = None, cwd: Path | None = None, timeout: float = 180):
    """``activebonds ARGS`` in a fresh process: CompletedProcess with text output."""
    return subprocess.run(
        [str(ACTIVEBONDS), *map(str, args)],
        cwd=cwd,
        env=env(cache),
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def cli_many(commands: list[tuple], cache: Path | None = None, jobs: int = 2, timeout=180):
    """Several ``activebonds`` commands, at most ``jobs`` at a time. Each command is a tuple
    of arguments, optionally ending with a dict {"cwd": Path}. Returns CompletedProcesses."""
    results: list = [None] * len(commands)
    running: list = []
    queue = list(enumerate(commands))
    deadline = time.monotonic() + timeout * max(1, len(commands) // jobs + 1)
    while queue or running:
        while queue and len(running) < jobs:
            i, cmd = queue.pop(0)
            opts = cmd[-1] if cmd and isinstance(cmd[-1], dict) else {}
            args = cmd[:-1] if opts else cmd
            proc = subprocess.Popen(
                [str(ACTIVEBONDS), *map(str, args)],
                cwd=opts.get("cwd"),
                env=env(cache),
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
            )
            running.append((i, args, proc))
        i, args, proc = running.pop(0)
        try:
            out, err = proc.communicate(timeout=max(1.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
        results[i] = subprocess.CompletedProcess(args, proc.returncode, out, err)
    return results


def runner_argv(*args) -> list[str]:
    return [sys.executable, str(RUNNER), *map(str, args)]


def fit_argv(ws: dict, problem: str, out: Path, seed: int | None = None, throttle: float = 0.0):
    """The runner's command line for the kill/resume problem ``problem`` into ``out``."""
    spec = PROBLEMS[problem]
    argv = runner_argv(
        "fit",
        ws["base"] / spec["model"],
        ws["base"] / spec["data"],
        out,
        "--seed", FIT["seed"] if seed is None else seed,
        "--population", FIT["population"],
        "--generations", FIT["generations"],
        "--checkpoint-every", FIT["checkpoint_every"],
        "--chunk", FIT["chunk"],
        *spec["extra"],
    )  # fmt: skip
    if throttle:
        argv += ["--throttle", str(throttle)]
    return argv


# ----------------------------------------------------------------------------- shared state
_MEMO: dict = {}


def workspace(tmp_path_factory) -> dict:
    """Copies of the inputs (tests may point run.json at their own copies and edit those),
    the 30-frame triangle recording, and a compilation cache folder; once per process."""
    if "ws" not in _MEMO:
        from activebonds.data import write_trajectory
        from activebonds.model import load_model
        from activebonds.simulation import simulate

        base = tmp_path_factory.mktemp("reliability")
        shutil.copyfile(EXAMPLES / "triangle.toml", base / "triangle.toml")
        shutil.copyfile(EXAMPLES / "horse_limb.toml", base / "horse_limb.toml")
        shutil.copyfile(HORSE_TROT, base / "horse_trot.csv")
        traj = simulate(load_model(EXAMPLES / "triangle.toml"), n_frames=30, rate=60.0)
        write_trajectory(traj, base / "triangle.csv")
        cache = base / "jax-cache"
        cache.mkdir()
        _MEMO["ws"] = {"base": base, "cache": cache}
    return _MEMO["ws"]


def reference(tmp_path_factory, problem: str = "triangle") -> Path:
    """An uninterrupted runner fit of ``problem`` with the kill/resume settings (memoised).
    It compiles into the shared cache, which later subprocesses then reuse."""
    key = ("ref", problem)
    if key not in _MEMO:
        ws = workspace(tmp_path_factory)
        out = ws["base"] / f"ref-{problem}"
        t0 = time.monotonic()
        proc = subprocess.run(
            fit_argv(ws, problem, out),
            env=env(ws["cache"]),
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        assert proc.returncode == 0, proc.stderr
        _MEMO[key] = out
        _MEMO[("ref-seconds", problem)] = time.monotonic() - t0
    return _MEMO[key]


def copy_run(run: Path, dest: Path) -> Path:
    shutil.copytree(run, dest)
    return dest


def point_inputs(run: Path, **paths: Path) -> None:
    """Rewrite run.json so that input ``name`` is recorded at ``path`` (same content)."""
    meta = json.loads((run / "run.json").read_text())
    for name, path in paths.items():
        meta["inputs"][name]["path"] = str(Path(path).resolve())
    (run / "run.json").write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")


def edit_meta(run: Path, edit) -> None:
    meta = json.loads((run / "run.json").read_text())
    edit(meta)
    (run / "run.json").write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")


def result_bytes(run: Path) -> tuple[bytes, bytes]:
    return (run / "history.csv").read_bytes(), (run / "best_model.toml").read_bytes()


def checkpoint_arrays(path: Path) -> dict:
    import numpy as np

    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def complete_checkpoints(run: Path) -> list[int]:
    """Generations of the checkpoints that load completely and are self-consistent, read
    independently of the package (and without removing anything)."""
    out = []
    for path in sorted((run / "checkpoints").glob("gen-*.npz")):
        try:
            arrays = checkpoint_arrays(path)
            gen = int(arrays["state_generation"])
            if any(len(v) != gen for k, v in arrays.items() if k.startswith("history_")):
                continue
            if path.name != f"gen-{gen:09d}.npz":
                continue
            out.append(gen)
        except Exception:  # noqa: BLE001 - anything unreadable is not complete
            continue
    return out


def leftovers(run: Path) -> list[str]:
    """Temporary files of interrupted atomic writes, in RUN/ and RUN/checkpoints/."""
    names = []
    for folder in (run, run / "checkpoints"):
        if folder.is_dir():
            names += [
                str(p.relative_to(run))
                for p in folder.iterdir()
                if p.name.startswith(".tmp-") or p.name.endswith(".tmp")
            ]
    return sorted(names)


def last_gen(log: Path) -> int | None:
    gens = [
        int(line.split()[1]) for line in log.read_text().splitlines() if line.startswith("gen ")
    ]
    return gens[-1] if gens else None


def one_line_error(proc) -> str:
    """The single stderr line of a refused command (asserts it is one line, no traceback)."""
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    return lines[0]


if __name__ == "__main__":
    sys.exit(main())
