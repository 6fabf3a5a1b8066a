"""Run an identification: compile, evolve in chunks, checkpoint, resume.

The Python API (usable from a notebook) and the ``fit`` / ``resume`` commands both go through
:func:`fit` and :func:`resume`. A run is a pure function of (model, data window, settings,
seed, software versions): the generation keys are derived from the seed and the generation
number, and a resumed run continues from the exact saved state, so it ends with the same
history and best model as an uninterrupted one.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ..atomic import write_text_atomic
from ..data import Trajectory, read_trajectory
from ..data.writers import render_npz
from ..errors import InputError
from ..model import Model, dumps_model, load_model, loads_model, save_model
from . import es, rundir
from .cost import rms_mm
from .problem import Identification, identification
from .settings import FitSettings

Progress = Callable[[int, int, float], None]  # (generation, total, best RMS mm)


@dataclass
class FitResult:
    """The outcome of a fit: the identified model and how well it reproduces the data."""

    model: Model  # best identified model (all parameters set)
    genome: np.ndarray  # its free parameters, search space
    cost: float  # summed squared one-step error (m^2)
    rms_mm: float  # RMS position error, millimetres
    local_rms_mm: dict[str, float]  # per particle
    history: dict[str, np.ndarray]
    identification: Identification
    settings: FitSettings
    status: str
    run: Path | None = None


def _precision(settings: FitSettings):
    """JAX's 64-bit mode for the run's precision, scoped to the call."""
    return jax.enable_x64(settings.precision == "float64")


def _dtype(settings: FitSettings):
    return jnp.float64 if settings.precision == "float64" else jnp.float32


def fit(
    model: Model | str | Path,
    data: Trajectory | str | Path,
    settings: FitSettings | None = None,
    out: str | Path | None = None,
    *,
    overwrite: bool = False,
    progress: Progress | None = None,
    **options,
) -> FitResult:
    """Identify the free parameters of ``model`` from ``data``.

    ``model`` and ``data`` are objects or file paths; ``settings`` a :class:`FitSettings`
    (or its fields as keyword ``options``). With ``out``, a run directory is written
    (settings, hashes, history, checkpoints, best model) and the run can be resumed.
    """
    settings = settings or FitSettings(**options)
    with _precision(settings):
        return _fit(model, data, settings, out, overwrite, progress)


def _fit(model, data, settings: FitSettings, out, overwrite: bool, progress) -> FitResult:
    model_path = Path(model) if isinstance(model, str | Path) else None
    data_path = Path(data) if isinstance(data, str | Path) else None
    model_obj = load_model(model_path) if model_path else model
    traj = read_trajectory(data_path) if data_path else data
    ident = identification(model_obj, traj, settings)
    run = None
    if out is not None:
        model_text = model_path.read_bytes() if model_path else dumps_model(model_obj).encode()
        run = _create_run(out, model_text, ident, settings, model_path, data_path, overwrite)
    return _evolve(ident, settings, run, None, None, progress)


def _create_run(out, model_text, ident, settings, model_path, data_path, overwrite) -> Path:
    inputs = {}
    for name, path in (("model", model_path), ("data", data_path)):
        if path is not None:
            inputs[name] = {"path": str(path.resolve()), "sha256": rundir.sha256_file(path)}
    meta = {
        "format": rundir.FORMAT,
        "settings": settings.model_dump(mode="json"),
        "seed": settings.seed,
        "inputs": inputs,
        "versions": rundir.versions(),
        "backend": rundir.backend(),
        "command": rundir.python_command(),
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
    files = {"model.toml": model_text, "data.npz": render_npz(ident.data, Path("data.npz"))}
    return rundir.create(out, files, meta, overwrite)


def _stored_identification(run: Path, settings: FitSettings) -> Identification:
    model = loads_model((run / "model.toml").read_text(encoding="utf-8"), str(run / "model.toml"))
    window = read_trajectory(run / "data.npz")
    return identification(model, window, settings.model_copy(update={"frames": (0, None)}))


def resume(
    run: str | Path,
    *,
    force: bool = False,
    generations: int | None = None,
    progress: Progress | None = None,
) -> FitResult:
    """Continue an interrupted run from its newest complete checkpoint.

    Refuses (one line, naming what changed) if the model file, the data file, the settings or
    the software versions differ from those recorded, unless ``force``. ``generations`` may
    extend the run.
    """
    run = Path(run)
    meta = rundir.read_meta(run)
    try:
        settings = FitSettings(**meta["settings"])
    except Exception as err:  # noqa: BLE001 - report any bad settings as one line
        raise InputError(run / "run.json", f"settings are not valid ({err})") from None
    if not force:
        _check_unchanged(run, meta)
    if generations is not None:
        if generations < 1:
            raise InputError("--generations", "must be at least 1")
        settings = settings.model_copy(update={"generations": generations})
    with _precision(settings):
        return _resume(run, settings, progress)


def _resume(run: Path, settings: FitSettings, progress) -> FitResult:
    ident = _stored_identification(run, settings)
    n, g = settings.population, ident.model.layout.n_genes
    p = ident.model.topology.n_particles
    shapes = {"genes": (n, g), "sigma": (n, g), "cost": (n,), "local": (n, p)}
    state, history, skipped = rundir.load_checkpoint(run, shapes)
    if state is None and skipped:
        raise InputError(run, "no complete checkpoint to resume from" + _skipped(skipped))
    # No checkpoint at all: the run was stopped before its first one; start it afresh.
    return _evolve(ident, settings, run, state, history, progress)


def _skipped(skipped: list[str]) -> str:
    return f" (unreadable: {', '.join(skipped)})" if skipped else ""


def _check_unchanged(run: Path, meta: dict) -> None:
    for name, rec in meta.get("inputs", {}).items():
        path = Path(rec["path"])
        if not path.is_file():
            raise InputError(
                run, f"the {name} file {path} is gone; pass --force to use the copy in the run"
            )
        if rundir.sha256_file(path) != rec["sha256"]:
            raise InputError(
                run,
                f"the {name} file {path} changed since the run started; pass --force to continue anyway",
            )
    now = rundir.versions()
    for pkg, version in meta.get("versions", {}).items():
        if now.get(pkg) != version:
            raise InputError(
                run,
                f"{pkg} version changed ({version} -> {now.get(pkg)}); pass --force to continue anyway",
            )
    stored = rundir.read_status(run).get("job")
    current = FitSettings(**meta["settings"]).job()
    if stored is not None and stored != current:
        changed = sorted(k for k in set(stored) | set(current) if stored.get(k) != current.get(k))
        detail = ", ".join(f"{k} {stored.get(k)!r} -> {current.get(k)!r}" for k in changed)
        raise InputError(
            run / "run.json",
            f"settings changed since the run started ({detail}); pass --force to continue anyway",
        )


def _to_numpy(state: es.ESState) -> dict[str, np.ndarray]:
    return {k: np.asarray(v) for k, v in state._asdict().items()}


def _from_numpy(arrays: dict[str, np.ndarray], dtype) -> es.ESState:
    return es.ESState(
        genes=jnp.asarray(arrays["genes"], dtype),
        sigma=jnp.asarray(arrays["sigma"], dtype),
        cost=jnp.asarray(arrays["cost"], dtype),
        local=jnp.asarray(arrays["local"], dtype),
        variant_probs=jnp.asarray(arrays["variant_probs"], dtype),
        generation=jnp.asarray(arrays["generation"], jnp.int32),
        failed_total=jnp.asarray(arrays["failed_total"], jnp.int32),
    )


def _rows(rows: es.GenerationRow, active, first_gen: int, n_terms: int) -> dict[str, np.ndarray]:
    act = np.asarray(active)
    k = int(act.sum())
    best = np.asarray(rows.best)[act]
    out = {
        "generation": np.arange(first_gen + 1, first_gen + k + 1),
        "best_cost": best,
        "median_cost": np.asarray(rows.median)[act],
        "worst_cost": np.asarray(rows.worst)[act],
        "best_rms_mm": rms_mm(best, n_terms),
        "failed": np.asarray(rows.failed)[act],
    }
    trials, succ = np.asarray(rows.trials)[act], np.asarray(rows.successes)[act]
    for i in range(4):
        out[f"trials_v{i + 1}"] = trials[:, i]
        out[f"successes_v{i + 1}"] = succ[:, i]
    return out


def _evolve(ident, settings: FitSettings, run, state_np, history, progress) -> FitResult:
    dtype = _dtype(settings)
    problem = ident.problem._replace(evaluate=_cast(ident.problem.evaluate, dtype))
    es_settings = settings.es()
    init_key, gen_key = jax.random.split(jax.random.PRNGKey(settings.seed))
    n_terms = ident.windows.n_terms
    total = settings.generations

    if state_np is None:
        state = jax.jit(partial(es.init, problem=problem, settings=es_settings, dtype=dtype))(
            init_key
        )
        history = {c: np.zeros(0) for c in rundir.HISTORY_COLUMNS}
        if not np.isfinite(np.asarray(state.cost)).any():
            return _finish(
                ident,
                settings,
                run,
                state,
                history,
                "failed: every candidate's simulation went non-finite",
            )
    else:
        state = _from_numpy(state_np, dtype)
    chunk = jax.jit(
        partial(es.run, problem=problem, settings=es_settings, n_generations=settings.chunk)
    )
    gen = int(state.generation)
    last_ckpt = gen
    if run is not None and state_np is None:
        _checkpoint(run, ident, settings, state, history, "running")
    started = time.time()
    if progress is not None and gen > 0 and len(history["best_rms_mm"]):
        progress(gen, total, float(history["best_rms_mm"][-1]))  # a resumed run starts here
    try:
        while gen < total:
            state, (rows, active) = chunk(gen_key, state, stop=total)
            new = _rows(rows, active, gen, n_terms)
            history = {k: np.concatenate([history[k], new[k]]) for k in history}
            gen = int(state.generation)
            if progress is not None:
                progress(gen, total, float(history["best_rms_mm"][-1]))
            if run is not None and (gen - last_ckpt >= settings.checkpoint_every) and gen < total:
                _checkpoint(run, ident, settings, state, history, "running", started)
                last_ckpt = gen
    except KeyboardInterrupt:
        if run is not None:
            _checkpoint(run, ident, settings, state, history, "interrupted", started)
        raise
    return _finish(ident, settings, run, state, history, "completed", started)


NOISE_BUDGET = 64 * 2**20  # bytes of random numbers drawn per compiled chunk


def chunk_length(problem, es_settings, requested: int, runs: int = 1) -> int:
    """Generations per compiled chunk: as requested, fewer if their random numbers would
    exceed NOISE_BUDGET. Results do not depend on it (see es.run)."""
    per_generation = es.noise_bytes(problem, es_settings) * runs
    return int(max(1, min(requested, NOISE_BUDGET // per_generation)))


def _cast(evaluate, dtype):
    def cast(genome):
        cost, local = evaluate(genome)
        return cost.astype(dtype), local.astype(dtype)

    return cast


def _best(ident: Identification, state) -> tuple[np.ndarray, float, np.ndarray]:
    genome, cost, local = es.best(state)
    return np.asarray(genome, np.float64), float(cost), np.asarray(local, np.float64)


def _checkpoint(run, ident, settings, state, history, status, started=None) -> None:
    rundir.save_checkpoint(run, _to_numpy(state), history)
    write_text_atomic(run / "history.csv", rundir.history_csv(history))
    genome, cost, _ = _best(ident, state)
    if np.isfinite(cost):
        save_model(ident.model.with_genome(genome), run / "best_model.toml")
    rundir.write_status(
        run,
        status=status,
        generation=int(state.generation),
        generations=settings.generations,
        best_rms_mm=float(rms_mm(cost, ident.windows.n_terms)) if np.isfinite(cost) else None,
        failed_evaluations=int(state.failed_total),
        job=settings.job(),
        wall_seconds=None if started is None else round(time.time() - started, 3),
    )


def _finish(ident, settings, run, state, history, status, started=None) -> FitResult:
    genome, cost, local = _best(ident, state)
    n_terms = ident.windows.n_terms
    per_particle = ident.windows.weight.sum(axis=(0, 1))
    model = ident.model.with_genome(genome) if np.isfinite(cost) else ident.model
    if run is not None:
        _checkpoint(run, ident, settings, state, history, status, started)
    return FitResult(
        model=model,
        genome=genome,
        cost=cost,
        rms_mm=float(rms_mm(cost, n_terms)),
        local_rms_mm={
            name: float(rms_mm(c, int(w)))
            for name, c, w in zip(ident.model.particle_names, local, per_particle, strict=True)
        },
        history=history,
        identification=ident,
        settings=settings,
        status=status,
        run=run,
    )


__all__ = ["FitResult", "FitSettings", "fit", "resume"]
