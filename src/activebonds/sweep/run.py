"""Run a sweep's fits: as Ray tasks (locally or on a cluster), or one after another.

Each fit is :func:`run_job`, the same whichever way it runs. It looks at its run directory
(``OUT/NAME``) and does what is left: nothing for a finished run; :func:`~activebonds.identify.resume`
for a run with a checkpoint (interrupted, killed, or finished with fewer generations than the
manifest now asks); :func:`~activebonds.identify.fit` otherwise. A run is a pure function of its
model, data, settings and seed, however often it was stopped, so rerunning a sweep (or Ray
retrying the task of a worker that died) ends with the results of an uninterrupted sweep.

While a fit runs, ``OUT/.running/NAME.pid`` holds the process id and host of the worker that
runs it (left behind by a worker that was killed; replaced by the next attempt).
"""

from __future__ import annotations

import logging
import os
import socket
import sys
import warnings
from pathlib import Path

from ..errors import InputError
from ..identify import fit, resume
from ..identify.rundir import RunDir
from .manifest import Job
from .outcome import Done, Outcome
from .summary import row

MAX_RETRIES = 3  # attempts after a worker dies (each resumes from the newest checkpoint)
STOP_SECONDS = 60.0  # after Ctrl-C, how long running fits get to save their checkpoints
RUNNING = ".running"  # OUT/.running/NAME.pid: which worker process runs which fit


# ----------------------------------------------------------------------------- one fit


def run_job(job: Job, out: str | Path, command: list[str] | None = None) -> Outcome:
    """Bring the run of ``job`` under ``out`` to its end (see the module docstring) and
    measure it for the summary. Errors of the fit become an outcome, not an exception; a
    Ctrl-C (KeyboardInterrupt) is raised after the fit saved its checkpoint. ``command``:
    the sweep's command line, recorded in a new run's run.json (default: this process's)."""
    out = Path(out)
    run = out / job.name
    pid_file = mark_running(out, job.name)
    try:
        action = _advance(job, run, command)
        status, message = RunDir(run).status().get("status", "unknown"), ""
    except InputError as err:
        action, status, message = "error", "error", err.line()
    except Exception as err:  # noqa: BLE001 - one fit's failure does not stop the sweep
        action, status, message = "error", "error", f"{type(err).__name__}: {err}"
    finally:
        pid_file.unlink(missing_ok=True)
    try:
        measured = row(run)
    except Exception as err:  # noqa: BLE001 - a run that cannot be measured is still reported
        measured = {}
        message = message or f"not measured for the summary ({type(err).__name__}: {err})"
    return Outcome(job.name, action, status, " ".join(message.split()), measured)


def _advance(job: Job, run: Path, command: list[str] | None) -> str:
    planned = job.settings.generations
    if RunDir(run).is_run():
        st = RunDir(run).status()
        # failed: not one finite candidate to start from, which more generations do not change
        if st.get("status") == "failed" or (
            st.get("status") == "completed" and st.get("generations") == planned
        ):
            return "skipped"
        # a checkpoint to continue from (or none yet: resume then starts afresh)
        resume(run, generations=planned)
        return "resumed"
    RunDir(run).remove_partial()  # a create that was killed
    fit(job.model, job.data_arg, job.settings, out=run, command=command)
    return "ran"


def mark_running(out: Path, name: str) -> Path:
    """``out/.running/NAME.pid``: the process id and host of the worker running ``name``
    (left behind by a worker that was killed; replaced by the next attempt)."""
    folder = out / RUNNING
    folder.mkdir(exist_ok=True)
    path = folder / f"{name}.pid"
    path.write_text(f"{os.getpid()} {socket.gethostname()}\n")
    return path


# ----------------------------------------------------------------------------- before running


def check_out(jobs: list[Job], out: str | Path) -> None:
    """Refuse (:class:`InputError`) an output folder whose runs are not the manifest's: a
    run directory of other settings or inputs, more generations, or something else where
    a run directory goes. Nothing is written."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(out, "exists and is not a folder; choose another --out")
    if not out.absolute().parent.is_dir():
        raise InputError(out, f"the parent folder {out.absolute().parent} does not exist")
    for job in jobs:
        run = out / job.name
        if not run.exists():
            continue
        if not RunDir(run).is_run():
            raise InputError(
                run, "exists and is not a run directory; move it away or choose another --out"
            )
        _check_run(job, run, RunDir(run).meta())


def _check_run(job: Job, run: Path, meta: dict) -> None:
    recorded = RunDir(run).settings(meta)
    then, now = recorded.job(), job.settings.job()
    changed = sorted(k for k in then if then[k] != now.get(k))
    if changed:
        detail = ", ".join(f"{k} {then[k]!r} -> {now.get(k)!r}" for k in changed)
        raise InputError(
            run,
            f"holds a run of other settings ({detail}); move it away or choose another --out",
        )
    total = int(RunDir(run).status().get("generations", recorded.generations))
    if total > job.settings.generations:
        raise InputError(
            run,
            f"holds a run of {total} generations, more than the manifest's "
            f"{job.settings.generations}; move it away or choose another --out",
        )
    named = [("model", job.model)] + [
        ("data" if i == 0 else f"data-{i + 1}", p) for i, p in enumerate(job.data)
    ]
    inputs = meta.get("inputs", {})
    for name, path in named:
        rec = inputs.get(name, {})
        if rec.get("path") != str(path) or rec.get("sha256") != RunDir.sha256(path):
            raise InputError(
                run,
                f"holds a run of another {name} file ({rec.get('path', 'none')}, not {path} "
                "as it is now); move it away or choose another --out",
            )
    if set(inputs) != {n for n, _ in named}:
        raise InputError(
            run, "holds a run of other recordings; move it away or choose another --out"
        )


# ----------------------------------------------------------------------------- running


def ray_available() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def run_sequential(jobs: list[Job], out: str | Path, done: Done) -> list[Outcome]:
    """Every fit in this process, one after another; ``done`` hears of each."""
    outcomes = []
    try:
        for job in jobs:
            outcomes.append(run_job(job, out))
            done(outcomes[-1])
    finally:
        tidy(Path(out))
    return outcomes


def use_ray(workers: int | None, address: str | None, sequential: bool) -> bool:
    """Whether the command line's work runs on Ray, from its ``--workers``, ``--address`` and
    ``--sequential`` (InputError naming an option that cannot be: Ray without it installed,
    this machine's options with a cluster's)."""
    if workers is not None and workers < 1:
        raise InputError("--workers", "must be at least 1")
    if address is not None and (workers is not None or sequential):
        option = "--workers" if workers is not None else "--sequential"
        raise InputError(option, "is for this machine; --address runs on the cluster's CPUs")
    ray = not sequential and ray_available()
    if address is not None and not ray:
        raise InputError("--address", "needs Ray: pip install 'activebonds[ray]'")
    return ray


def where(workers: int | None, address: str | None) -> str:
    """Where Ray runs the work, in words."""
    if address:
        return f"the Ray cluster at {address}"
    return f"a local Ray cluster of {workers or os.cpu_count()} workers"


def start_ray(workers: int | None = None, address: str | None = None) -> bool:
    """Start a local Ray cluster of ``workers`` CPUs or join the one at ``address`` (raises
    :class:`InputError` if it cannot be reached). Returns whether this call connected (so
    it is this caller's to shut down); a connection already made is used as it is."""
    import ray

    if ray.is_initialized():
        return False
    options = {"logging_level": logging.ERROR, "log_to_driver": False}
    try:
        with warnings.catch_warnings():
            # Ray's processes are started by fork-exec, which JAX's warning does not tell apart
            warnings.filterwarnings("ignore", "os.fork", RuntimeWarning)
            if address is None:  # local workers inherit this process's environment
                ray.init("local", num_cpus=workers, include_dashboard=False, **options)
            else:
                ray.init(address=address, runtime_env={"env_vars": worker_env()}, **options)
    except (ConnectionError, RuntimeError, ValueError) as err:
        raise InputError("--address" if address else "ray", " ".join(str(err).split())) from None
    return True


def worker_env() -> dict[str, str]:
    """What a cluster's workers take from this process's environment: the XLA flags (the
    same compiled code, the same numbers) and the compilation cache's setting."""
    return {k: os.environ[k] for k in ("XLA_FLAGS", "ACTIVEBONDS_CACHE") if k in os.environ}


def ray_task(job: Job, out: str, command: list[str]) -> Outcome:
    """:func:`run_job` in a Ray worker, a process of its own: it keeps compiled programs
    between runs, as the command line does."""
    from ..runtime import compilation_cache

    compilation_cache()
    return run_job(job, out, command)


def run_ray(jobs: list[Job], out: str | Path, done: Done) -> list[Outcome]:
    """Every fit as a Ray task (:func:`ray_each`) on the cluster this process is connected
    to (:func:`start_ray`); ``done`` hears of each as it ends. A task whose worker died is
    retried (:data:`MAX_RETRIES`) and resumes from its checkpoint. On Ctrl-C the running
    fits are cancelled (each saves a checkpoint first) and KeyboardInterrupt is raised."""
    out = Path(out).absolute()
    outcomes = []

    def finished(outcome: Outcome) -> None:
        outcomes.append(outcome)
        done(outcome)

    try:
        ray_each(ray_task, jobs, (str(out), list(sys.argv)), finished,
                 lambda job, err: _lost(job, out, err))  # fmt: skip
    finally:
        tidy(out)
    return outcomes


def ray_each(fn, items: list, args: tuple, finished, lost) -> None:
    """``fn(item, *args)`` for every item as a Ray task of one CPU, retried
    (:data:`MAX_RETRIES`) where its worker died; ``finished(result)`` as each ends, the
    result ``lost(item, error)`` for a task whose workers died every time. On Ctrl-C the
    running tasks are cancelled (a KeyboardInterrupt in each, which saves its checkpoint),
    given :data:`STOP_SECONDS` to end, and KeyboardInterrupt is raised."""
    import ray

    task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES, retry_exceptions=False)(fn)
    refs = {task.remote(item, *args): item for item in items}
    pending = list(refs)
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                try:
                    result = ray.get(ref)
                except ray.exceptions.RayError as err:  # its workers died MAX_RETRIES + 1 times
                    result = lost(refs[ref], err)
                finished(result)
    except KeyboardInterrupt:
        for ref in pending:
            ray.cancel(ref)
        ray.wait(pending, num_returns=len(pending), timeout=STOP_SECONDS)
        raise


def tidy(out: Path) -> None:
    """OUT/.running removed once no work runs (it stays if a killed worker left a mark)."""
    try:
        (out / RUNNING).rmdir()
    except OSError:
        pass


def first_line(err: Exception) -> str:
    """An error's first line, or its type's name."""
    return (str(err).strip().splitlines() or [type(err).__name__])[0]


def _lost(job: Job, out: Path, err: Exception) -> Outcome:
    message = f"{type(err).__name__}: {first_line(err)}; rerun the sweep to resume it"
    return Outcome(job.name, "error", "lost", message, row(out / job.name))
