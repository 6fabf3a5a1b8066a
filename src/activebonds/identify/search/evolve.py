"""The one evolve loop: any strategy, one run or several seeds at once, in compiled chunks.

A generation is fused: ``ask``, the vmapped evaluation (non-finite -> +inf, counted),
``tell``. Many generations run in one compiled ``lax.scan`` (a chunk) whose random numbers
are drawn first, in bulk; generation g's numbers depend only on the seed key and g, so
results do not depend on how a run is chunked, interrupted or resumed. Generations at or
beyond ``stop`` leave the state unchanged, so a compiled chunk may run past the end.

Chunks are sized by time (:class:`Chunking`): about :data:`CHUNK_SECONDS` each, from the
measured time of a generation (first estimated from the start's population evaluation), never
more generations than remain, and at most ``requested``; a short final chunk is compiled only
where that is cheaper than running a compiled one past the end. So short fits are short, and
progress and interrupts stay responsive on big models. Used by ``fit``/``resume``
(driver.py), the multi-seed experiments and the benchmarks.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .strategy import Column, Problem, Strategy, finite_or_inf

NOISE_BUDGET = 64 * 2**20  # bytes of random numbers drawn per compiled chunk
DEFAULT_CHUNK = 250  # generations per compiled chunk, at most
CHUNK_SECONDS = 1.0  # wall time aimed at per chunk


class Run(NamedTuple):
    """The loop's state: the strategy's state, and what the loop itself counts."""

    strategy: Any
    generation: jax.Array  # int32: generations done
    failed_total: jax.Array  # int32: non-finite evaluations so far


def population_evaluate(problem: Problem, dtype) -> Callable:
    """genes [N, G] -> (cost [N], local [N, P]) in ``dtype``, non-finite -> +inf."""

    each = problem.evaluate_population or jax.vmap(problem.evaluate)

    def evaluate(genes):
        cost, local = each(genes)
        out = dtype or jnp.result_type(float)
        return finite_or_inf(cost.astype(out), local.astype(out))

    return evaluate


def start(strategy: Strategy, problem: Problem, dtype, key) -> Run:
    """The strategy's first state; every failed evaluation it made is counted."""
    evaluate = population_evaluate(problem, dtype)
    failures = []

    def counted(genes):
        cost, local = evaluate(genes)
        failures.append(jnp.sum(~jnp.isfinite(cost)).astype(jnp.int32))
        return cost, local

    state = strategy.init(key, counted)
    failed = sum(failures[1:], failures[0]) if failures else jnp.asarray(0, jnp.int32)
    return Run(state, jnp.asarray(0, jnp.int32), failed)


def _start_from(strategy: Strategy, problem: Problem, dtype, key, starts) -> Run:
    """:func:`start` with the problem's start genomes ``starts`` (an argument of the program,
    or None)."""
    if starts is not None:
        problem = problem._replace(start=starts)
        strategy = dataclasses.replace(strategy, problem=problem)
    return start(strategy, problem, dtype, key)


def step(strategy: Strategy, problem: Problem, dtype, noise, run: Run):
    """One generation from its random numbers: (new loop state, history row)."""
    genes, aux = strategy.ask(noise, run.strategy)
    cost, local = population_evaluate(problem, dtype)(genes)
    failed = jnp.sum(~jnp.isfinite(cost)).astype(jnp.int32)
    state, row = strategy.tell(noise, run.strategy, aux, cost, local)
    new = Run(state, run.generation + 1, run.failed_total + failed)
    return new, {**row, "failed": failed}


def chunk(strategy: Strategy, problem: Problem, dtype, n: int, base_key, run: Run, stop):
    """``n`` generations in one ``lax.scan``; those at or beyond ``stop`` change nothing.
    Returns (state, (rows, active))."""
    indices = run.generation + jnp.arange(n, dtype=jnp.int32)
    noises = jax.vmap(lambda g: strategy.draw(jax.random.fold_in(base_key, g)))(indices)

    def body(s, nz):
        new, row = step(strategy, problem, dtype, nz, s)
        active = s.generation < stop
        s = jax.tree.map(lambda a, b: jnp.where(active, a, b), new, s)
        return s, (row, active)

    return jax.lax.scan(body, run, noises)


def chunk_length(strategy: Strategy, requested: int, total: int | None = None, runs: int = 1):
    """Generations per compiled chunk: at most ``requested`` and the generations of the run,
    fewer if their random numbers would exceed NOISE_BUDGET."""
    per_generation = max(1, strategy.noise_bytes * runs)
    n = min(requested, NOISE_BUDGET // per_generation)
    if total is not None:
        n = min(n, total)
    return int(max(1, n))


def keys(seed: int):
    """(init key, generation key) of a seed."""
    return jax.random.split(jax.random.PRNGKey(seed))


class Chunking:
    """Chooses each chunk's length from measured times: about :data:`CHUNK_SECONDS` a chunk,
    at most ``limit`` generations; compiled lengths are reused where that costs less than
    compiling another (a compilation is timed as it happens)."""

    def __init__(self, limit: int, seconds: float = CHUNK_SECONDS):
        self.limit, self.seconds = limit, seconds
        self.generation: float | None = None  # seconds per generation, measured
        self.estimate: float | None = None  # seconds per generation, before any chunk ran
        self.compile = 0.0  # seconds of the slowest compilation seen

    def target(self) -> int:
        per = self.generation or self.estimate
        if per is None:
            return min(self.limit, 16)
        return int(max(1, min(self.limit, self.seconds / max(per, 1e-9))))

    def next(self, remaining: int, compiled) -> int:
        """The length of the next chunk, ``remaining`` generations to go."""
        target = min(self.target(), remaining)
        if not compiled:
            return target
        per = self.generation or self.estimate or 0.0
        if remaining > self.target():  # the body of the run: a length near the target
            near = [c for c in compiled if target / 4 <= c <= 2 * target]
            if near:
                return max(near)
            # shorter chunks only cost their calls' overhead: compile the target length only
            # where the rest of the run is long beside a compilation
            short = [c for c in compiled if c < target]
            if short and remaining * per < 10 * self.compile:
                return max(short)
            return target

        def cost(c):  # time to finish with length c (compiling it if new)
            calls = -(-remaining // c)
            return calls * c * per + (0.0 if c in compiled else self.compile)

        options = [c for c in compiled if c * per <= 2 * self.seconds] + [remaining]
        return min(options, key=cost)

    def observed(self, n: int, seconds: float) -> None:
        self.generation = seconds / n


class Evolution:
    """Compiled start and chunks of one strategy on one problem; ``seeds`` runs them side by
    side (vmapped: they share the compiled code and the vector width). ``display`` turns
    costs into what people read (the cost's :class:`~activebonds.identify.costs.windows.Display`).
    ``requested`` caps the generations of a chunk; within it, chunks are sized by time."""

    def __init__(
        self,
        strategy: Strategy,
        problem: Problem,
        dtype,
        *,
        total: int,
        requested: int = DEFAULT_CHUNK,
        display,
        seeds: int | None = None,
    ):
        self.strategy, self.problem, self.dtype = strategy, problem, dtype
        self.display, self.seeds = display, seeds
        self.columns = history_columns(strategy, display)
        self.length = chunk_length(strategy, requested, total, seeds or 1)
        self.chunking = Chunking(self.length)
        # the problem's start genomes an argument, not a constant of the program: a model of
        # the same structure and other values loads this one's program
        self._starts = None if problem.start is None else np.asarray(problem.start)
        one_start = partial(_start_from, strategy, problem, dtype)
        if seeds is None:
            self._start = jax.jit(one_start)
        else:
            self._start = jax.jit(jax.vmap(one_start, in_axes=(0, None)))
        self._jitted: dict[int, Any] = {}
        self._compiled: dict[int, Any] = {}

    def chunk_function(self, n: int):
        """The jitted chunk of ``n`` generations: ``(gen_key, state, stop) -> (state, rows)``."""
        if n not in self._jitted:
            one_chunk = partial(chunk, self.strategy, self.problem, self.dtype, n)
            if self.seeds is None:
                self._jitted[n] = jax.jit(one_chunk)
            else:
                self._jitted[n] = jax.jit(jax.vmap(one_chunk, in_axes=(0, 0, None)))
        return self._jitted[n]

    @property
    def chunk_fn(self):
        """The jitted chunk of the longest length (:attr:`length`), for the benchmarks."""
        return self.chunk_function(self.length)

    def start(self, init_key) -> Run:
        """The first state; its time (one population evaluation, compiled apart) estimates a
        generation's for the first chunk's length."""
        began = time.perf_counter()
        compiled = self.compiled_start(init_key)
        self.chunking.compile = max(self.chunking.compile, time.perf_counter() - began)
        began = time.perf_counter()
        state = jax.block_until_ready(compiled(init_key))
        self.chunking.estimate = time.perf_counter() - began
        return state

    def template(self, init_key) -> Run:
        """Shapes and dtypes of the loop state, without computing it (for checkpoints)."""
        return jax.eval_shape(self._start, init_key, self._starts)

    def compiled_start(self, init_key):
        """``key -> first state``, compiled ahead (the start genomes passed in)."""
        compiled = self._start.lower(init_key, self._starts).compile()
        return lambda key: compiled(key, self._starts)

    def _call(self, n: int, gen_key, state: Run, stop: int):
        if n not in self._compiled:
            began = time.perf_counter()
            self._compiled[n] = self.chunk_function(n).lower(gen_key, state, stop).compile()
            self.chunking.compile = max(self.chunking.compile, time.perf_counter() - began)
        began = time.perf_counter()
        out = jax.block_until_ready(self._compiled[n](gen_key, state, stop))
        self.chunking.observed(n, time.perf_counter() - began)
        return out

    def run(
        self, gen_key, state: Run, stop: int, every: int | None = None
    ) -> Iterator[tuple[Run, dict[str, np.ndarray]]]:
        """Chunks until ``stop`` generations are done: yields (state, history rows of the
        chunk, as NumPy columns by name; [seeds, k] when vmapped). With ``every``, no chunk
        crosses a multiple of ``every`` (the checkpoints' generations)."""
        while (done := _generation(state)) < stop:
            end = stop if every is None else min(stop, (done // every + 1) * every)
            n = self.chunking.next(end - done, tuple(self._compiled))
            state, (rows, active) = self._call(n, gen_key, state, end)
            yield state, self.rows(rows, active, state)

    def rows(self, rows: dict, active, state: Run) -> dict[str, np.ndarray]:
        act = np.asarray(active)
        act = act if act.ndim == 1 else act[0]
        done = _generation(state)
        k = int(act.sum())
        out: dict[str, np.ndarray] = {"generation": np.arange(done - k + 1, done + 1)}
        for col in self.columns[1:]:
            if col.field in rows:
                out[col.name] = _pick(np.asarray(rows[col.field]), act, col)
        for col in self.strategy.columns:
            if col.name in self.strategy.cost_columns:
                out[self.display.column(col.name)] = self.display(out[col.name])
        return {c.name: out[c.name] for c in self.columns}


def _pick(values: np.ndarray, act: np.ndarray, col: Column) -> np.ndarray:
    """Rows of the active generations (axis -1 for scalar fields, -2 for vector ones)."""
    if col.index is not None:
        values = values[..., col.index]
    return values[..., act]


def _generation(state: Run) -> int:
    return int(np.asarray(state.generation).reshape(-1)[0])


def history_columns(strategy: Strategy, display) -> tuple[Column, ...]:
    """The columns of a run's history: the generation, the strategy's cost columns, the same
    shown through the cost's display (e.g. ``best_rms_mm``), the failures, and the
    strategy's other columns."""
    costs = [c for c in strategy.columns if c.name in strategy.cost_columns]
    shown = [Column(display.column(c.name), "") for c in costs]
    others = [c for c in strategy.columns if c.name not in strategy.cost_columns]
    return (
        Column("generation", "generation", integer=True),
        *costs,
        *shown,
        Column("failed", "failed", integer=True),
        *others,
    )
