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
from dataclasses import dataclass, field
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ..data import Trajectory, read_trajectory
from ..data.writers import render_npz
from ..errors import InputError
from ..model import Model, dumps_model, load_model
from . import rundir, strategies, uncertainty
from .cost import Display
from .evolve import Evolution, history_columns, keys
from .problem import Identification, identification
from .refine import Refinement, Stage
from .settings import FitSettings

Progress = Callable[[int, int, float], None]  # (generation, total, best RMS mm)
# What the run does next, for people, before a phase that may take long with no progress to
# show: "compiling the cost and the evolution strategy", "refining ...", "estimating ...".
Status = Callable[[str], None]


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
    refinement: list[Stage] = field(default_factory=list)  # the stages after the ES, if any
    es_genome: np.ndarray | None = None  # the ES's best, before any refinement


def _precision(settings: FitSettings):
    """JAX's 64-bit mode for the run's precision, scoped to the call."""
    return jax.enable_x64(settings.precision != "float32")


def _dtype(settings: FitSettings):
    return jnp.float32 if settings.precision == "float32" else jnp.float64


def fit(
    model: Model | str | Path,
    data: Trajectory | str | Path | list,
    settings: FitSettings | None = None,
    out: str | Path | None = None,
    *,
    overwrite: bool = False,
    progress: Progress | None = None,
    status: Status | None = None,
    command: list[str] | None = None,
    **options,
) -> FitResult:
    """Identify the free parameters of ``model`` from ``data``.

    ``model`` and ``data`` are objects or file paths (``data`` may be a list of several
    recordings, fitted at once: their costs add up); ``settings`` a :class:`FitSettings`
    (or its fields as keyword ``options``). With ``out``, a run directory is written
    (settings, hashes, history, checkpoints, best model) and the run can be resumed; a folder
    without the free space the run needs is refused up front, and a write that fails later
    raises :class:`~activebonds.identify.rundir.RunWriteError` with the newest checkpoint
    kept. ``progress`` is called after each chunk of generations, ``status`` before the long
    silent phases (compilation, refinement, uncertainty) with what happens. ``command`` is
    the command line run.json records (default: this process's, ``sys.argv``).
    """
    settings = settings or FitSettings(**options)
    with _precision(settings):
        return _fit(model, data, settings, out, overwrite, progress, status, command)


def _fit(
    model, data, settings: FitSettings, out, overwrite: bool, progress, status=None, command=None
):
    model_path = Path(model) if isinstance(model, str | Path) else None
    many = isinstance(data, list | tuple)
    items = list(data) if many else [data]
    paths = [Path(d) if isinstance(d, str | Path) else None for d in items]
    model_obj = load_model(model_path) if model_path else model
    trajs = [read_trajectory(p) if p else d for p, d in zip(paths, items, strict=True)]
    ident = identification(model_obj, trajs if many else trajs[0], settings)
    run = None
    if out is not None:
        model_text = model_path.read_bytes() if model_path else dumps_model(model_obj).encode()
        run = _create_run(out, model_text, ident, settings, model_path, paths, overwrite, command)
    return _evolve(ident, settings, run, progress, status=status)


def _create_run(
    out, model_text, ident, settings, model_path, data_paths, overwrite, command=None
) -> Path:
    inputs = {}
    named = [("model", model_path)] + [
        ("data" if i == 0 else f"data-{i + 1}", p) for i, p in enumerate(data_paths)
    ]
    for name, path in named:
        if path is not None:
            inputs[name] = {"path": str(path.resolve()), "sha256": rundir.sha256_file(path)}
    strategy = strategies.make(settings.optimizer, ident.problem, settings, _dtype(settings))
    display = Display(ident.windows.n_terms)
    meta = rundir.new_meta(
        settings, inputs, strategy.name, history_columns(strategy, display), display, command
    )
    files = {"model.toml": model_text}
    for i, d in enumerate(ident.all_data):
        files[rundir.data_name(i)] = render_npz(d, Path(rundir.data_name(i)))
    n_particles = len(ident.model.particle_names)
    state = _state_bytes(strategy, n_particles, _dtype(settings))
    need = rundir.expected_bytes(state, len(meta["history"]["columns"]), settings.generations)
    need += 2 * sum(len(v) for k, v in files.items() if k != "model.toml")  # refinement states
    return rundir.create(out, files, meta, overwrite, need_bytes=need)


def _state_bytes(strategy, n_particles: int, dtype) -> int:
    """Bytes of the strategy's state (its shapes, traced with a stand-in cost: nothing is
    computed or compiled), plus the loop's counters."""

    def evaluate(genes):
        n = genes.shape[0]
        return jnp.zeros(n, dtype), jnp.zeros((n, n_particles), dtype)

    shapes = jax.eval_shape(lambda key: strategy.init(key, evaluate), jax.random.PRNGKey(0))
    return sum(8 * int(np.prod(leaf.shape)) for leaf in jax.tree.leaves(shapes)) + 16


def _stored_identification(run: Path, settings: FitSettings) -> Identification:
    model, windows = rundir.read_input_model(run), rundir.read_windows(run)
    data = windows if len(windows) > 1 else windows[0]
    return identification(model, data, settings.model_copy(update={"frames": (0, None)}))


def resume(
    run: str | Path,
    *,
    force: bool = False,
    generations: int | None = None,
    progress: Progress | None = None,
    status: Status | None = None,
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
        return _resume(run, meta, settings, progress, status)


def _resume(run: Path, meta: dict, settings: FitSettings, progress, status=None) -> FitResult:
    ident = _stored_identification(run, settings)
    if meta.get("upgraded_from"):  # a run of an older format continues in the current one
        rundir.write_meta(run, {k: v for k, v in meta.items() if k != "upgraded_from"})
    return _evolve(ident, settings, run, progress, resuming=True, status=status)


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
    if stored is not None and meta.get("upgraded_from") == 1:
        stored = {"optimizer": "es", **stored}  # format 1 had the paper's ES only
    current = FitSettings(**meta["settings"]).job()
    if stored is not None and stored != current:
        changed = sorted(k for k in set(stored) | set(current) if stored.get(k) != current.get(k))
        detail = ", ".join(f"{k} {stored.get(k)!r} -> {current.get(k)!r}" for k in changed)
        raise InputError(
            run / "run.json",
            f"settings changed since the run started ({detail}); pass --force to continue anyway",
        )


def _evolve(
    ident: Identification,
    settings: FitSettings,
    run: Path | None,
    progress,
    resuming=False,
    status=None,
):
    """Start (or, with a run directory holding a checkpoint, continue) the run and evolve it
    to ``settings.generations``, checkpointing every ``checkpoint_every`` generations and on
    Ctrl-C."""
    dtype = _dtype(settings)
    problem = ident.problem._replace(evaluate=_cast(ident.problem.evaluate, dtype))
    strategy = strategies.make(settings.optimizer, problem, settings, dtype)
    display = Display(ident.windows.n_terms)
    total = settings.generations
    loop = Evolution(
        strategy, problem, dtype, total=total, requested=settings.chunk, display=display
    )
    init_key, gen_key = keys(settings.seed)
    integer = {c.name for c in loop.columns if c.integer}
    saved = None
    if resuming:
        template = loop.template(init_key)
        shapes = rundir.state_shapes(template)
        saved = rundir.load_checkpoint(run, shapes)
        if saved[0] is None and saved[2]:
            raise InputError(run, "no complete checkpoint to resume from" + _skipped(saved[2]))
        _check_space_to_resume(run, shapes, len(loop.columns), total)
    if saved is not None and saved[0] is not None:
        arrays, history, _ = saved
        history = rundir.upgrade_history(history, rundir.read_meta(run))
        state = rundir.unflatten_state(arrays, template)
    else:  # a new run, or one stopped before its first checkpoint: start afresh
        state = loop.start(init_key)
        history = {c.name: np.zeros(0) for c in loop.columns}
        if not np.isfinite(float(strategy.best(state.strategy)[1])):
            failed = "failed: every candidate's simulation went non-finite"
            return _finish(ident, settings, run, strategy, state, history, integer, failed)
        if run is not None:
            _checkpoint(run, ident, settings, strategy, state, history, integer, "running")
    gen = last_ckpt = int(state.generation)
    started = time.time()
    if progress is not None and gen > 0 and len(history["best_rms_mm"]):
        progress(gen, total, float(history["best_rms_mm"][-1]))  # a resumed run starts here
    if status is not None and gen < total:
        status(compiling_text(strategy.name))
    try:
        every = settings.checkpoint_every if run is not None else None
        for latest, rows in loop.run(gen_key, state, total, every):
            state = latest
            history = {k: np.concatenate([history[k], rows[k]]) for k in history}
            gen = int(state.generation)
            if progress is not None:
                progress(gen, total, float(history["best_rms_mm"][-1]))
            if run is not None and (gen - last_ckpt >= settings.checkpoint_every) and gen < total:
                args = (run, ident, settings, strategy, state, history, integer)
                _checkpoint(*args, "running", started)
                last_ckpt = gen
    except KeyboardInterrupt:
        if run is not None:
            args = (run, ident, settings, strategy, state, history, integer)
            _checkpoint(*args, "interrupted", started)
        raise
    args = (ident, settings, run, strategy, state, history, integer, "completed", started)
    return _finish(*args, say=status)


def _check_space_to_resume(run: Path, shapes: dict, columns: int, total: int) -> None:
    """Refuse (one line) to resume in a folder without the space the rest of the run needs:
    what the run writes in all, less what it holds now (replaced as it goes), and at least
    one more checkpoint beside the kept ones."""
    state = rundir.state_bytes(shapes)
    need = rundir.expected_bytes(state, columns, total) - rundir.used_bytes(run)
    one = state + total * columns * 8
    rundir.check_space(run, run, max(need, one), "resuming writes")


def compiling_text(optimizer: str) -> str:
    """What a fit does before its first generations, for people."""
    words = {"es": "evolution strategy", "cmaes": "CMA-ES", "random": "random search"}
    return f"compiling the cost and the {words.get(optimizer, optimizer)}"


def _cast(evaluate, dtype):
    def cast(genome):
        cost, local = evaluate(genome)
        return cost.astype(dtype), local.astype(dtype)

    return cast


def _best(strategy, state) -> tuple[np.ndarray, float, np.ndarray]:
    genome, cost, local = strategy.best(state.strategy)
    return np.asarray(genome, np.float64), float(cost), np.asarray(local, np.float64)


def _checkpoint(run, ident, settings, strategy, state, history, integer, status, started=None):
    rundir.save_checkpoint(run, rundir.flatten_state(state), history)
    rundir.write_history(run, history, integer)
    genome, cost, _ = _best(strategy, state)
    display = Display(ident.windows.n_terms)
    if np.isfinite(cost):
        rundir.save_best_model(run, ident.model.with_genome(genome))
    rundir.write_status(
        run,
        status=status,
        generation=int(state.generation),
        generations=settings.generations,
        best_rms_mm=float(display(cost)) if np.isfinite(cost) else None,
        failed_evaluations=int(state.failed_total),
        job=settings.job(),
        wall_seconds=None if started is None else round(time.time() - started, 3),
    )


def _finish(
    ident, settings, run, strategy, state, history, integer, status, started=None, *, say=None
):
    genome, cost, local = _best(strategy, state)
    display = Display(ident.windows.n_terms)
    if run is not None:
        _checkpoint(run, ident, settings, strategy, state, history, integer, status, started)
    es_genome, stages, states = genome, [], None
    if status == "completed" and settings.refine != "none" and np.isfinite(cost):
        if run is not None:
            rundir.write_status(run, **{**rundir.read_status(run), "status": "refining"})
        if say is not None:
            n = len(settings.horizon)
            say(f"refining the best model (Levenberg-Marquardt, {n} stage{'s' * (n > 1)})")
        genome, stages, states = _refine(ident, settings, run, genome, int(state.generation))
        cost, local = (np.asarray(a, np.float64) for a in jax.jit(ident.problem.evaluate)(genome))
        cost = float(cost)
        if run is not None:
            rundir.save_best_model(run, ident.model.with_genome(genome))
            done = {"status": status, "best_rms_mm": float(display(cost))}
            rundir.write_status(run, **{**rundir.read_status(run), **done})
    if run is not None and status == "completed" and np.isfinite(cost):
        if say is not None:
            say("estimating the uncertainty of the parameters")
        _uncertainty(ident, settings, run, genome, stages, states)
    per_particle = ident.windows.weight.sum(axis=(0, 1))
    model = ident.model.with_genome(genome) if np.isfinite(cost) else ident.model
    return FitResult(
        model=model,
        genome=genome,
        cost=cost,
        rms_mm=float(display(cost)),
        local_rms_mm={
            name: float(Display(int(w))(c))
            for name, c, w in zip(ident.model.particle_names, local, per_particle, strict=True)
        },
        history=history,
        identification=ident,
        settings=settings,
        status=status,
        run=run,
        refinement=stages,
        es_genome=es_genome,
    )


def _refine(ident, settings, run, genome, generation) -> tuple[np.ndarray, list[Stage]]:
    """The refinement stages after the ES's best ``genome`` (generation ``generation``): those
    a resumed run already finished are read back, the others run and are saved one by one."""
    refinement = Refinement(ident, settings)
    stages: list[Stage] = []
    record, states = rundir.load_refinement(run) if run is not None else (None, None)
    start = [float(g) for g in genome]
    if (
        record is not None
        and record.get("from_generation") == generation
        and record.get("from_genome") == start
    ):
        stages = [Stage(**r) for r in record["stages"]][: len(settings.horizon)]
        refinement.states = states
    current = np.asarray(stages[-1].genome) if stages else genome
    for horizon in settings.horizon[len(stages) :]:
        stage = refinement.stage(horizon, current)
        stages.append(stage)
        current = np.asarray(stage.genome)
        if run is not None:
            record = {
                "from_generation": generation,
                "from_genome": start,
                "cost": settings.cost,
                "horizons": list(settings.horizon),
                "stages": [s.record() for s in stages],
            }
            rundir.save_refinement(run, record, refinement.states)
    return current, stages, refinement.states


def _uncertainty(ident, settings, run, genome, stages, states) -> None:
    """RUN/uncertainty.csv and .json: the Gauss-Newton report at the fit's optimum, on the
    cost of its last accepted stage (the ES's cost without refinement)."""
    last = next((s for s in reversed(stages) if s.accepted), None)
    horizon = last.horizon if last else settings.es_horizon
    cost = last.cost if last else "restart"
    try:
        report = uncertainty.estimate(ident, settings, genome, horizon, cost, states)
    except (MemoryError, ValueError, np.linalg.LinAlgError) as err:
        rundir.write_uncertainty_skipped(run, str(err))
        return
    rundir.write_uncertainty(run, report)


__all__ = ["FitResult", "FitSettings", "fit", "resume"]
