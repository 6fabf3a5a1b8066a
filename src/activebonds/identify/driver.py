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

from ..data import Trajectory
from ..data.writers import render_npz
from ..errors import InputError
from ..model import Model, dumps_model
from ..runtime import keep_compiled
from . import stages
from .costs.windows import Display
from .prepare import Prepared, prepare
from .problem import Identification, identification
from .progress import shown
from .rundir import RunDir
from .search import strategies
from .search.evolve import Evolution, history_columns, keys
from .settings import FitSettings
from .solvers.refine import Stage

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
    # the post-fit stages' records by name (identify.stages: refine, baselines, uncertainty,
    # validation, ...), as RUN/NAME.json holds them
    records: dict[str, dict] = field(default_factory=dict)

    def __repr__(self) -> str:
        """One line for notebooks: the model, the error, the verdict, the status, no arrays."""
        from .judge.verdict import short_text

        stages = f", {len(self.refinement)} refinement stages" if self.refinement else ""
        run = f", run={str(self.run)!r}" if self.run is not None else ""
        zero = self.baselines.get("zero_force_rms_mm")
        judged = ""
        if zero is not None:
            judged = f" (zero force {zero:.4g} mm)"
        if self.verdict is not None:
            judged += f", {short_text(self.verdict)}"
        return (
            f"FitResult({self.model!r}, rms {self.rms_mm:.4g} mm{judged}, status "
            f"{self.status!r}, {self.settings.optimizer} {self.settings.population} x "
            f"{self.settings.generations}{stages}{run})"
        )

    def _repr_html_(self) -> str:
        """A small table for notebooks: the model, the error beside its baselines, the
        verdict, the search and the run."""
        from ..notebook import html_table, number
        from .judge.verdict import fit_verdict
        from .stages.baselines import FLOOR, LSQ, ZERO

        s = self.settings
        rows: list[tuple[str, object]] = [
            ("model", repr(self.model)),
            ("RMS one-step error", number(self.rms_mm, "mm")),
        ]
        for key, name in (
            ("zero_force_rms_mm", ZERO),
            ("momentum_floor_rms_mm", FLOOR),
            ("least_squares_rms_mm", LSQ),
        ):
            if self.baselines.get(key) is not None:
                rows.append((name, number(self.baselines[key], "mm")))
        if (found := fit_verdict(self.records)) is not None:
            rows.append((f"verdict, {found[0]}, one step", found[1].text()))
        rows += [
            ("status", self.status),
            ("search", f"{s.optimizer}, population {s.population} x {s.generations} generations"),
            ("genes", f"{len(self.genome)} free parameters"),
        ]
        if self.refinement:
            rows.append(("refinement", f"{len(self.refinement)} stages"))
        if self.run is not None:
            rows.append(("run directory", str(self.run)))
        return html_table("FitResult", rows)

    @property
    def baselines(self) -> dict[str, float]:
        """The fit's baselines on the fitted frames, RMS one-step errors in mm:
        ``zero_force_rms_mm`` (constant velocity, every fitted recording) and, for the plain
        one-step cost, ``momentum_floor_rms_mm`` (no model of internal forces goes below it)
        and ``least_squares_rms_mm`` (the exact optimum of a model whose parameters are all
        linear; None otherwise). Empty when the baselines stage did not run (a failed
        fit)."""
        record = self.records.get("baselines") or {}
        keys = ("zero_force_rms_mm", "momentum_floor_rms_mm", "least_squares_rms_mm")
        return {k: record[k] for k in keys if k in record}

    @property
    def comparisons(self) -> dict[str, list]:
        """The model beside zero force (:class:`~activebonds.identify.judge.verdict.Comparison`:
        one step and K frames ahead, overall and per marker): ``"fitted"`` on the fitted
        frames (the first recording) and ``"held_out"`` on the validation frames, where
        those stages ran."""
        from .judge.verdict import judged_comparisons

        return judged_comparisons(self.records)

    @property
    def verdict(self):
        """The one-step :class:`~activebonds.identify.judge.verdict.Verdict` on the held-out frames
        when there are some, else on the fitted frames (None before the baselines ran):
        ``result.verdict.better``, ``.gain_pct``, ``.text()``."""
        from .judge.verdict import fit_verdict

        found = fit_verdict(self.records)
        return None if found is None else found[1]

    def lines(self) -> list[str]:
        """What the post-fit stages say of this fit, one line each, in their order."""
        return [
            line
            for stage in stages.stages()
            if stage.name in self.records
            for line in stage.lines(self.records[stage.name])
        ]


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
    progress: Progress | bool | None = None,
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
    kept. ``command`` is the command line run.json records (default: this process's,
    ``sys.argv``). ``cost="auto"`` chooses the refinement's cost for the recording
    (:mod:`activebonds.identify.costs.choice`); ``model`` may be what
    :func:`~activebonds.identify.prepare.prepare` returned (its inputs read and checked).

    ``progress=True`` shows a progress bar, in a notebook (Jupyter) or a terminal: the
    generation, the best RMS error, the time, and what the fit does in its silent phases
    (compilation, refinement, baselines, uncertainty). A function instead is called after
    each chunk of generations with ``(generation, total, best_rms_mm)``, and ``status``
    with a line of text before each silent phase:

    ```python
    seen = []
    result = fit("model.toml", "data.csv", generations=500,
                 progress=lambda g, total, rms: seen.append((g, rms)))
    ```
    """
    clock = Clock()
    if not isinstance(model, Prepared):
        settings = settings or FitSettings(**options)
        given = "horizon" in settings.model_fields_set  # else auto's cost has its own
        model = prepare(model, data, settings, horizon_given=given)
    settings = model.settings
    keep_compiled()  # a second fit of the same shapes loads this one's programs
    with _precision(settings), shown(progress, status) as (progress, status):
        return _fit(model, out, overwrite, progress, status, command, clock)


class Clock:
    """The run's wall time over all its sessions (status.json's ``wall_seconds``): the total
    of the sessions before this one (read when it resumes) plus this one's, counted from the
    call of ``fit`` or ``resume``: reading, compiling, the search and every post-fit stage.
    Written at each checkpoint and after each post-fit stage (a killed session loses the time
    since its last write)."""

    def __init__(self, before: float = 0.0):
        self.before, self.start = float(before), time.time()

    def seconds(self) -> float:
        return round(self.before + time.time() - self.start, 3)


def _fit(prepared: Prepared, out, overwrite: bool, progress, status=None, command=None, clock=None):
    settings = prepared.settings
    ident = identification(prepared.model, prepared.data, settings)
    held_out = prepared.held_out
    run = None
    if out is not None:
        path = prepared.model_path
        model_text = path.read_bytes() if path else dumps_model(prepared.model).encode()
        run = _create_run(
            out, model_text, ident, settings, path, prepared.paths, overwrite, command, held_out
        )
    return _evolve(ident, settings, run, progress, status=status, held_out=held_out, clock=clock)


def _create_run(
    out, model_text, ident, settings, model_path, data_paths, overwrite, command=None, held_out=None
) -> RunDir:
    inputs = {}
    named = [("model", model_path)] + [
        ("data" if i == 0 else f"data-{i + 1}", p) for i, p in enumerate(data_paths)
    ]
    for name, path in named:
        if path is not None:
            inputs[name] = {"path": str(path.resolve()), "sha256": RunDir.sha256(path)}
    strategy = strategies.make(settings.optimizer, ident.problem, settings, _dtype(settings))
    display = Display(ident.windows.n_terms)
    meta = RunDir.new_meta(
        settings, inputs, strategy.name, history_columns(strategy, display), display, command
    )
    files = {"model.toml": model_text}
    for i, d in enumerate(ident.all_data):
        files[RunDir.data_name(i)] = render_npz(d, Path(RunDir.data_name(i)))
    n_particles = len(ident.model.particle_names)
    state = _state_bytes(strategy, n_particles, _dtype(settings))
    need = RunDir.expected_bytes(state, len(meta["history"]["columns"]), settings.generations)
    need += 2 * sum(len(v) for k, v in files.items() if k != "model.toml")  # refinement states
    return RunDir.create(out, files, meta, overwrite, need_bytes=need, held_out=held_out)


def _state_bytes(strategy, n_particles: int, dtype) -> int:
    """Bytes of the strategy's state (its shapes, traced with a stand-in cost: nothing is
    computed or compiled), plus the loop's counters."""

    def evaluate(genes):
        n = genes.shape[0]
        return jnp.zeros(n, dtype), jnp.zeros((n, n_particles), dtype)

    shapes = jax.eval_shape(lambda key: strategy.init(key, evaluate), jax.random.PRNGKey(0))
    return sum(8 * int(np.prod(leaf.shape)) for leaf in jax.tree.leaves(shapes)) + 16


def _stored_identification(run: RunDir, settings: FitSettings) -> Identification:
    model, windows = run.input_model(), run.windows()
    data = windows if len(windows) > 1 else windows[0]
    return identification(model, data, settings.model_copy(update={"frames": (0, None)}))


def resume(
    run: str | Path,
    *,
    force: bool = False,
    generations: int | None = None,
    progress: Progress | bool | None = None,
    status: Status | None = None,
) -> FitResult:
    """Continue an interrupted run from its newest complete checkpoint.

    Refuses (one line, naming what changed) if the model file, the data file, the settings or
    the software versions differ from those recorded, unless ``force``. ``generations`` may
    extend the run. ``progress`` and ``status`` as :func:`fit`'s.
    """
    run = RunDir(run)
    meta = run.meta()
    settings = run.settings(meta)
    if not force:
        run.check_unchanged(meta)
    if generations is not None:
        if generations < 1:
            raise InputError("--generations", "must be at least 1")
        settings = settings.model_copy(update={"generations": generations})
    before = run.status().get("wall_seconds")
    clock = Clock(before if isinstance(before, int | float) else 0.0)
    keep_compiled()
    with _precision(settings), shown(progress, status) as (progress, status):
        return _resume(run, meta, settings, progress, status, clock)


def _resume(
    run: RunDir, meta: dict, settings: FitSettings, progress, status=None, clock=None
) -> FitResult:
    ident = _stored_identification(run, settings)
    if meta.get("upgraded_from"):  # a run of an older format continues in the current one
        run.write_meta({k: v for k, v in meta.items() if k != "upgraded_from"})
    held_out = run.held_out()
    return _evolve(ident, settings, run, progress, True, status, held_out=held_out, clock=clock)


def _skipped(skipped: list[str]) -> str:
    return f" (unreadable: {', '.join(skipped)})" if skipped else ""


def _evolve(
    ident: Identification,
    settings: FitSettings,
    run: RunDir | None,
    progress,
    resuming=False,
    status=None,
    *,
    held_out=None,
    clock: Clock | None = None,
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
        shapes = RunDir.state_shapes(template)
        saved = run.load_checkpoint(shapes)
        if saved[0] is None and saved[2]:
            raise InputError(run.path, "no complete checkpoint to resume from" + _skipped(saved[2]))
        _check_space_to_resume(run, shapes, len(loop.columns), total)
    if saved is not None and saved[0] is not None:
        arrays, history, _ = saved
        history = RunDir.upgrade_history(history, run.meta())
        state = RunDir.unflatten_state(arrays, template)
    else:  # a new run, or one stopped before its first checkpoint: start afresh
        state = loop.start(init_key)
        history = {c.name: np.zeros(0) for c in loop.columns}
        if not np.isfinite(float(strategy.best(state.strategy)[1])):
            failed = "failed: every candidate's simulation went non-finite"
            args = (ident, settings, run, strategy, state, history, integer, failed, clock)
            return _finish(*args, held_out=held_out)
        if run is not None:
            args = (run, ident, settings, strategy, state, history, integer)
            _checkpoint(*args, "running", clock)
    gen = last_ckpt = int(state.generation)
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
                _checkpoint(*args, "running", clock)
                last_ckpt = gen
    except KeyboardInterrupt:
        if run is not None:
            args = (run, ident, settings, strategy, state, history, integer)
            _checkpoint(*args, "interrupted", clock)
        raise
    args = (ident, settings, run, strategy, state, history, integer, "completed", clock)
    return _finish(*args, say=status, held_out=held_out)


def fitted_model(ident: Identification, settings: FitSettings, genome) -> Model:
    """The identified model with its start: every particle's position and velocity at the
    first frame of the fitted window of the first recording (the first frame there with the
    next one complete), the velocity the model's own step carries to the next frame
    (:func:`~activebonds.simulation.start_at`); so ``simulate``, ``evaluate`` and ``export``
    take the model file as it is. Without such a frame, the model as fitted."""
    from ..simulation import start_at

    model = ident.model.with_genome(genome)
    mask = np.asarray(ident.data.mask, bool).all(axis=1)
    both = np.flatnonzero(mask[:-1] & mask[1:])
    if both.size == 0:
        return model
    data = ident.data  # the fitted columns in particle order (--markers may rename them)
    data = Trajectory(data.positions, data.mask, model.markers, data.rate, source=data.source)
    try:
        return start_at(model, data, int(both[0]), settings.substeps, settings.integrator)
    except InputError:
        return model


def _check_space_to_resume(run: RunDir, shapes: dict, columns: int, total: int) -> None:
    """Refuse (one line) to resume in a folder without the space the rest of the run needs:
    what the run writes in all, less what it holds now (replaced as it goes), and at least
    one more checkpoint beside the kept ones."""
    state = RunDir.state_bytes(shapes)
    need = RunDir.expected_bytes(state, columns, total) - run.used_bytes()
    one = state + total * columns * 8
    run.check_space(max(need, one), "resuming writes")


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


def _checkpoint(run, ident, settings, strategy, state, history, integer, status, clock=None):
    run.save_checkpoint(RunDir.flatten_state(state), history)
    run.write_history(history, integer)
    genome, cost, _ = _best(strategy, state)
    display = Display(ident.windows.n_terms)
    if np.isfinite(cost):
        run.save_best_model(fitted_model(ident, settings, genome))
    run.write_status(
        status=status,
        generation=int(state.generation),
        generations=settings.generations,
        best_rms_mm=float(display(cost)) if np.isfinite(cost) else None,
        failed_evaluations=int(state.failed_total),
        job=settings.job(),
        wall_seconds=None if clock is None else clock.seconds(),
    )


def _finish(
    ident,
    settings,
    run,
    strategy,
    state,
    history,
    integer,
    status,
    clock=None,
    *,
    say=None,
    held_out=None,
):
    genome, cost, local = _best(strategy, state)
    display = Display(ident.windows.n_terms)
    if run is not None:
        _checkpoint(run, ident, settings, strategy, state, history, integer, status, clock)
    es_genome = genome
    fit = stages.Fit(ident, settings, genome, int(state.generation), status, run, held_out, say)
    records: dict[str, dict] = {}
    if np.isfinite(cost):
        for stage in stages.stages():
            if not stage.applies(fit):
                continue
            new = _run_stage(stage, fit, records, clock)
            if new is not None:  # a better model (the refinement)
                cost, local = (
                    np.asarray(a, np.float64) for a in jax.jit(ident.problem.evaluate)(new)
                )
                cost = float(cost)
                fit.genome = genome = new
                if run is not None:
                    run.save_best_model(fitted_model(ident, settings, genome))
                    run.update_status(status=status, best_rms_mm=float(display(cost)))
    per_particle = ident.windows.weight.sum(axis=(0, 1))
    model = fitted_model(ident, settings, genome) if np.isfinite(cost) else ident.model
    refined = fit.products.get("refine", ([], None))[0]
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
        run=None if run is None else run.path,
        refinement=refined,
        es_genome=es_genome,
        records=records,
    )


def _wall(clock) -> dict:
    return {} if clock is None else {"wall_seconds": clock.seconds()}


def _run_stage(stage, fit: stages.Fit, records: dict, clock=None) -> np.ndarray | None:
    """Run one post-fit stage (continuing from what it saved), save its record, hand its
    product on, the run's wall time brought up to date; returns its genome if it changed the
    best model. A stop asked before it starts (Ctrl-C during a stage that cannot stop midway:
    the baselines, the uncertainty, the substeps check) ends the fit there, resumable."""
    from ..runtime import stop_requested

    run = fit.run
    if stop_requested():  # a Ctrl-C during the last stage's uninterruptible work: stop here
        if run is not None:
            run.update_status(status="interrupted", **_wall(clock))
        raise KeyboardInterrupt
    if run is not None and stage.state is not None:
        run.update_status(status=stage.state)
    if fit.say is not None:
        fit.say(stage.doing(fit))
    saved, arrays = run.load_record(stage.name) if run is not None else (None, {})
    try:
        outcome = stage.run(fit, saved, arrays)
    except KeyboardInterrupt:  # Ctrl-C at a stage's safe point: it saved what it had
        if run is not None:
            run.update_status(status="interrupted", **_wall(clock))
        raise
    records[stage.name] = outcome.record
    if run is not None:
        run.save_record(stage.name, outcome.record, arrays=outcome.arrays, files=outcome.files)
        if stage.state is not None:
            run.update_status(status=fit.status)
        if clock is not None:
            run.update_status(**_wall(clock))
    if outcome.product is not None:
        fit.products[stage.name] = outcome.product
    return None if outcome.genome is None else np.asarray(outcome.genome, np.float64)


__all__ = ["FitResult", "FitSettings", "fit", "resume"]
