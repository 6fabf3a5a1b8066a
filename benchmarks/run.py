"""Benchmarks of the package's ES core, with baselines measured in the same run.

    python benchmarks/run.py [--quick] [--json out.json] [--only paper,scale,numpy,peers,ttt,long]

Sections (see benchmarks/README.md for what every column means):

* paper  - the paper's horse (3 markers, frames 0:10), populations 100/500/1000, standard and
           neural bonds: generations/s, evaluations/s, compile time;
* scale  - full horse (7 markers, 21 neural bonds) 10/60/600 frames, 35-particle mesh,
           horizon H = 1 vs H = 10 (pop 500);
* numpy  - the same ES in plain NumPy (benchmarks/numpy_es.py) vs ours, pair by pair;
* peers  - pycma CMA-ES (ask/tell around the package's jitted vmapped cost) and evosax
           CMA-ES / SNES (ask/eval/tell jitted in lax.scan) vs ours, pair by pair (pop 500);
* ttt    - time until every parameter of the synthetic triangle is within 1 % of the truth;
* long   - peak RSS and RSS growth over a long run of ours, through activebonds.identify.fit
           (a child process); in full mode this run is the paper's experiment end to end
           (500 x 50,000 generations, neural, compile included).

Our ES is measured through the package API exactly as driver.py runs it: the evolve loop's
start and a jitted chunk of generations (lax.scan), AOT-compiled with
``jax.jit(...).lower(...).compile()`` so that compile time is reported apart.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import problems as P  # noqa: E402  (imports activebonds: XLA flags, float64)
from activebonds.identify.costs.windows import Display  # noqa: E402
from activebonds.identify.search import es, evolve  # noqa: E402
from numpy_es import NumpyES  # noqa: E402

F64 = jnp.float64
BIG_STOP = 2**31 - 1
now = time.perf_counter


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # KiB on Linux


def _cast(evaluate, dtype=F64):
    """As driver._cast: the costs in the run's precision."""

    def cast(genome):
        cost, local = evaluate(genome)
        return cost.astype(dtype), local.astype(dtype)

    return cast


# ---------------------------------------------------------------------------------------------
# runners: each has .population, .compile_s, .call() -> seconds of one block, .block (gens)


class Ours:
    """The package's ES as driver.py runs it: the one evolve loop (identify/search/evolve.py) with
    the paper's strategy, its jitted start and a jitted chunk of generations (one lax.scan,
    the length the loop picks), called repeatedly with the state carried over."""

    label = "ours"

    def __init__(self, bench: P.Bench, population: int, chunk: int, seed: int = 0):
        settings = bench.settings.model_copy(update={"population": population})
        self.problem = bench.problem._replace(evaluate=_cast(bench.problem.evaluate))
        self.es_settings = settings.es()
        self.strategy = es.PaperES(self.problem, self.es_settings, F64)
        display = Display(bench.ident.windows.n_terms)
        self.loop = evolve.Evolution(
            self.strategy, self.problem, F64, total=BIG_STOP, requested=chunk, display=display
        )
        self.population, self.block = population, self.loop.length
        init_key, self.gen_key = evolve.keys(seed)
        t0 = now()
        init_c = self.loop.compiled_start(init_key)
        t1 = now()
        self.state = jax.block_until_ready(init_c(init_key))
        t2 = now()
        self.run_c = self.loop.chunk_fn.lower(self.gen_key, self.state, BIG_STOP).compile()
        t3 = now()
        self.compile_s = (t1 - t0) + (t3 - t2)
        self.init_s = t2 - t1

    def call(self) -> float:
        t = now()
        self.state, _ = self.run_c(self.gen_key, self.state, BIG_STOP)
        jax.block_until_ready(self.state)
        return now() - t

    def best_genome(self) -> np.ndarray:
        return np.asarray(self.strategy.best(self.state.strategy)[0])


class LeastSquares:
    """``fit --init lsq``'s start on its own: the exact linear least squares of the one-step
    cost (identify/solvers/lsq.py: NumPy, the fixed part's forces by JAX op by op, nothing compiled
    ahead). On the triangle every parameter enters linearly, so this is the one-step optimum."""

    label = "ours: exact least squares (--init lsq)"
    compile_s = 0.0
    population, block = 1, 1

    def __init__(self, bench: P.Bench):
        self.ident = bench.ident
        self.genome = bench.model.layout.initial()

    def call(self) -> float:
        from activebonds.identify.solvers.lsq import least_squares

        t = now()
        self.genome = least_squares(self.ident.model, self.ident.windows).genome
        return now() - t

    def best_genome(self) -> np.ndarray:
        return np.asarray(self.genome)


class Refined:
    """``activebonds.fit`` with the paper's ES (``generations`` of ``population``) and then
    ``--refine lm`` (one Levenberg-Marquardt stage on the one-step residuals), everything
    compiled inside the call (so ``compile_s`` is 0 here and the wall time holds it)."""

    label = "ours: ES + --refine lm"
    compile_s = 0.0

    def __init__(self, bench: P.Bench, population: int = 50, generations: int = 20):
        self.ident = bench.ident
        self.settings = bench.settings.model_copy(
            update={"population": population, "generations": generations, "refine": "lm"}
        )
        self.settings = self.settings.model_copy(update={"bonds": "model"})  # already a variant
        self.population, self.block = population, generations
        self.genome = bench.model.layout.initial()

    def call(self) -> float:
        from activebonds.identify import fit

        t = now()
        self.genome = fit(self.ident.model, self.ident.data, self.settings).genome
        return now() - t

    def best_genome(self) -> np.ndarray:
        return np.asarray(self.genome)


class Numpy:
    """The NumPy ES (benchmarks/numpy_es.py) on the same problem."""

    label = "NumPy ES"
    compile_s = 0.0

    def __init__(self, bench: P.Bench, population: int, block: int, seed: int = 0):
        settings = bench.settings.model_copy(update={"population": population}).es()
        self.population, self.block = population, block
        self.es = NumpyES.from_identification(bench.ident, settings, seed=seed).init()

    def call(self) -> float:
        t = now()
        self.es.run(self.block)
        return now() - t


def _unit_to_genome(lo, span):
    """Search space of the optimisers that know no bounds: u in [0, 1]^G, reflected once and
    clipped (as the package's ES reflects), mapped to the package's genome."""

    def to_genome(u):
        u = jnp.where(u < 0, -u, u)
        u = jnp.where(u > 1, 2 - u, u)
        return lo + span * jnp.clip(u, 0.0, 1.0)

    return to_genome


def default_popsize(n_genes: int) -> int:
    return 4 + int(3 * math.log(n_genes))


class PyCMA:
    """pycma's CMA-ES (ask/tell) in [0, 1]^G with bounds; evaluation by the package's cost,
    jitted and vmapped over the population (AOT-compiled for the population size)."""

    label = "pycma CMA-ES"

    def __init__(self, bench: P.Bench, popsize: int | None, block: int, seed: int = 1):
        import cma

        g = bench.n_genes
        lo, hi = np.asarray(bench.problem.lower), np.asarray(bench.problem.upper)
        self.to_genome = _unit_to_genome(jnp.asarray(lo), jnp.asarray(hi - lo))
        opts = {
            "bounds": [0.0, 1.0],
            "seed": seed,
            "verbose": -9,
            "tolfun": 0.0,
            "tolfunhist": 0.0,
            "tolx": 0.0,
            "tolflatfitness": 10**9,
            "maxiter": 10**12,
            "maxfevals": 10**15,
        }
        if popsize:
            opts["popsize"] = popsize
        self.es = cma.CMAEvolutionStrategy(0.5 * np.ones(g), 0.25, opts)
        self.population, self.block = self.es.popsize, block
        cost = _cast(bench.problem.evaluate)
        evaluate = jax.jit(lambda u: jax.vmap(cost)(self.to_genome(u))[0])
        t = now()
        self.evaluate = evaluate.lower(jax.ShapeDtypeStruct((self.population, g), F64)).compile()
        self.compile_s = now() - t
        self.t_ask = self.t_eval = self.t_tell = 0.0
        self.iterations = 0

    def step(self) -> None:
        t0 = now()
        x = self.es.ask()
        t1 = now()
        f = np.asarray(self.evaluate(np.asarray(x)))
        f = np.nan_to_num(f, nan=1e300, posinf=1e300)
        t2 = now()
        self.es.tell(x, f)
        t3 = now()
        self.t_ask += t1 - t0
        self.t_eval += t2 - t1
        self.t_tell += t3 - t2
        self.iterations += 1

    def call(self) -> float:
        t = now()
        for _ in range(self.block):
            self.step()
        return now() - t

    def overhead_share(self) -> float:
        total = self.t_ask + self.t_eval + self.t_tell
        return (self.t_ask + self.t_tell) / total if total else float("nan")

    def best_genome(self) -> np.ndarray:
        return np.asarray(self.to_genome(jnp.asarray(self.es.best.x)))


class Evosax:
    """An evosax strategy with ask -> package cost (vmapped) -> tell jitted in one lax.scan of
    ``block`` generations, AOT-compiled."""

    def __init__(self, bench: P.Bench, algo: str, popsize: int, block: int, seed: int = 0):
        from evosax.algorithms import CMA_ES, SNES

        self.label = f"evosax {algo}"
        g = bench.n_genes
        lo, hi = np.asarray(bench.problem.lower), np.asarray(bench.problem.upper)
        to_genome = _unit_to_genome(jnp.asarray(lo), jnp.asarray(hi - lo))
        self.to_genome = to_genome
        cls = {"CMA_ES": CMA_ES, "SNES": SNES}[algo]
        strategy = cls(population_size=popsize, solution=jnp.zeros(g))
        params = strategy.default_params.replace(std_init=jnp.asarray(0.25))
        cost = _cast(bench.problem.evaluate)
        self.population, self.block = popsize, block

        def generations(key, state):
            def body(carry, _):
                key, state = carry
                key, k_ask, k_tell = jax.random.split(key, 3)
                x, state = strategy.ask(k_ask, state, params)
                f = jax.vmap(cost)(to_genome(x))[0]
                f = jnp.where(jnp.isfinite(f), f, 1e300)
                state, _ = strategy.tell(k_tell, x, f, state, params)
                return (key, state), None

            (key, state), _ = jax.lax.scan(body, (key, state), None, length=block)
            return key, state

        key, k_init = jax.random.split(jax.random.PRNGKey(seed))
        t0 = now()
        init = jax.jit(lambda k: strategy.init(k, 0.5 * jnp.ones(g), params))
        init_c = init.lower(k_init).compile()
        t1 = now()
        self.state = jax.block_until_ready(init_c(k_init))
        self.key = key
        t2 = now()
        self.run_c = jax.jit(generations).lower(self.key, self.state).compile()
        self.compile_s = (t1 - t0) + (now() - t2)

    def call(self) -> float:
        t = now()
        self.key, self.state = self.run_c(self.key, self.state)
        jax.block_until_ready(self.state)
        return now() - t

    def best_genome(self) -> np.ndarray:
        return np.asarray(self.to_genome(self.state.best_solution))


# ---------------------------------------------------------------------------------------------
# measurements


def steady(runner, min_s: float, min_calls: int) -> dict:
    """First call, then calls until ``min_s`` seconds and ``min_calls`` calls; median."""
    first = runner.call()
    times: list[float] = []
    while sum(times) < min_s or len(times) < min_calls:
        times.append(runner.call())
    med = statistics.median(times)
    gps = runner.block / med
    return {
        "gens_per_s": gps,
        "evals_per_s": gps * runner.population,
        "compile_s": runner.compile_s,
        "first_call_extra_s": first - med,
        "block": runner.block,
        "calls": len(times),
        "measured_s": sum(times),
    }


def rate_for(runner, seconds: float) -> float:
    """Generations/s of ``runner`` over at least ``seconds`` (whole blocks, at least one)."""
    total, gens = 0.0, 0
    while total < seconds or gens == 0:
        total += runner.call()
        gens += runner.block
    return gens / total


def paired(a, b, seconds: float, repeats: int) -> dict:
    """a and b alternately (a, b, a, b, ...); ratio of generations/s per adjacent pair."""
    ra, rb, ratios = [], [], []
    for _ in range(repeats):
        x = rate_for(a, seconds)
        y = rate_for(b, seconds)
        ra.append(x)
        rb.append(y)
        ratios.append(x / y)
    return {
        "a": a.label,
        "b": b.label,
        "a_gens_per_s": statistics.median(ra),
        "b_gens_per_s": statistics.median(rb),
        "a_evals_per_s": statistics.median(ra) * a.population,
        "b_evals_per_s": statistics.median(rb) * b.population,
        "gens_ratio": statistics.median(ratios),
        "evals_ratio": statistics.median(ratios) * a.population / b.population,
        "gens_ratios": ratios,
    }


def config_row(section, bench, population, res, note="", label="ours") -> dict:
    return {
        "section": section,
        "config": bench.name,
        "optimizer": label,
        "description": bench.description,
        "population": population,
        **bench.shape(),
        **res,
        "note": note,
    }


def measure_ours(section, bench, population, chunk, opts, note="") -> dict:
    runner = Ours(bench, population, chunk)
    log(f"{section}: {bench.name} pop {population} (chunk {runner.block})")
    row = config_row(section, bench, population, steady(runner, opts.min_s, opts.min_calls), note)
    log(
        f"  {row['gens_per_s']:.1f} gen/s, {row['evals_per_s']:.0f} evals/s, "
        f"compile {row['compile_s']:.2f} s"
    )
    return row


def section_paper(opts) -> list[dict]:
    rows = []
    for bonds in ("standard", "neural"):
        bench = P.paper_horse(bonds)
        for pop in (100, 500, 1000):
            rows.append(measure_ours("paper", bench, pop, 250, opts))
    return rows


def section_scale(opts) -> list[dict]:
    q = opts.quick
    rows = []
    for frames, chunk in ((10, 100), (60, 25), (600, 2 if q else 5)):
        rows.append(measure_ours("scale", P.full_horse(frames), 500, chunk, opts))
    rows.append(measure_ours("scale", P.mesh(60), 500, 25, opts))
    for h in (1, 10):
        note = "H=1 vs H=10: same 60 frames, 58 vs 6 restarts"
        rows.append(measure_ours("scale", P.paper_horse("neural", 60, h), 500, 100, opts, note))
    return rows


def section_numpy(opts) -> list[dict]:
    bench = P.paper_horse("neural")
    out = []
    for pop in (500,) if opts.quick else (100, 500, 1000):
        log(f"numpy: pair ours / NumPy ES, {bench.name} pop {pop}")
        ours = Ours(bench, pop, 250)
        ours.call()
        numpy_es = Numpy(bench, pop, 20)
        numpy_es.call()
        res = paired(ours, numpy_es, opts.pair_s, opts.repeats)
        res.update(config=bench.name, population=pop)
        log(
            f"  ours {res['a_gens_per_s']:.1f} gen/s, NumPy {res['b_gens_per_s']:.1f} gen/s, "
            f"ratio {res['gens_ratio']:.2f}x"
        )
        out.append(res)
    return out


def section_peers(opts) -> dict:
    """Throughput at the paper's configuration (pop 500, neural), each paired with ours."""
    bench = P.paper_horse("neural")
    pop = 500
    log(f"peers: {bench.name} pop {pop}")
    ours = Ours(bench, pop, 250)
    ours.call()
    pairs, rows = [], []
    pycma = PyCMA(bench, pop, 5)
    pycma.call()
    res = paired(ours, pycma, opts.pair_s, opts.repeats)
    res.update(
        config=bench.name,
        population=pop,
        compile_s=pycma.compile_s,
        optimizer_overhead_share=pycma.overhead_share(),
        seconds_per_iteration={
            "ask": pycma.t_ask / pycma.iterations,
            "eval": pycma.t_eval / pycma.iterations,
            "tell": pycma.t_tell / pycma.iterations,
        },
    )
    log(
        f"  pycma {res['b_gens_per_s']:.1f} gen/s (ours {res['a_gens_per_s']:.1f}); "
        f"ask+tell {100 * res['optimizer_overhead_share']:.0f} % of its time"
    )
    pairs.append(res)
    rows.append(
        config_row(
            "peers",
            bench,
            pop,
            {
                "gens_per_s": res["b_gens_per_s"],
                "evals_per_s": res["b_evals_per_s"],
                "compile_s": pycma.compile_s,
                "first_call_extra_s": float("nan"),
            },
            f"ask+tell {100 * res['optimizer_overhead_share']:.0f} % of time",
            label=pycma.label,
        )
    )
    for algo in ("CMA_ES", "SNES"):
        peer = Evosax(bench, algo, pop, 50)
        first = peer.call()
        res = paired(ours, peer, opts.pair_s, opts.repeats)
        res.update(config=bench.name, population=pop, compile_s=peer.compile_s)
        log(f"  {peer.label} {res['b_gens_per_s']:.1f} gen/s (ours {res['a_gens_per_s']:.1f})")
        pairs.append(res)
        rows.append(
            config_row(
                "peers",
                bench,
                pop,
                {
                    "gens_per_s": res["b_gens_per_s"],
                    "evals_per_s": res["b_evals_per_s"],
                    "compile_s": peer.compile_s,
                    "first_call_extra_s": first - peer.block / res["b_gens_per_s"],
                },
                label=peer.label,
            )
        )
    return {"pairs": pairs, "rows": rows}


def time_to_target(make, model, truth, cap_s: float) -> dict:
    """Build (compile included) and run ``make()``'s optimiser until its best genome has every
    parameter within 1 % of ``truth``, checking after every block; at most ``cap_s``."""
    t0 = now()
    runner = make()
    compile_s = runner.compile_s
    gens = 0
    reached = False
    while now() - t0 < cap_s:
        runner.call()
        gens += runner.block
        if P.within(model, runner.best_genome(), truth):
            reached = True
            break
        stop = getattr(getattr(runner, "es", None), "stop", None)
        if callable(stop) and stop():
            break
    wall = now() - t0
    nat = model.layout.natural(runner.best_genome())
    err = float(np.max(np.abs(nat - truth) / np.abs(truth)))
    out = {
        "optimizer": runner.label,
        "population": runner.population,
        "reached": reached,
        "wall_s": wall,
        "wall_without_compile_s": wall - compile_s,
        "compile_s": compile_s,
        "generations": gens,
        "evaluations": gens * runner.population,
        "max_rel_error": err,
        "check_every": runner.block,
    }
    if not reached:
        es_ = getattr(runner, "es", None)
        out["stopped"] = dict(es_.stop()) if es_ is not None and hasattr(es_, "stop") else None
    log(
        f"  {runner.label}: {'reached' if reached else 'NOT reached'} in {wall:.2f} s "
        f"({wall - compile_s:.2f} s without compile), {gens} generations, "
        f"max rel error {err:.2e}"
    )
    return out


def section_ttt(opts) -> list[dict]:
    bench = P.triangle()
    truth = P.triangle_truth()
    model = bench.model
    popsize = default_popsize(bench.n_genes)
    cap = opts.ttt_cap
    log(f"ttt: {bench.name}, cap {cap:.0f} s, target: every parameter within 1 %")
    out = [  # the two that compile nothing ahead first: nothing of the triangle is warm yet
        time_to_target(lambda: LeastSquares(bench), model, truth, cap),
        time_to_target(lambda: Refined(bench), model, truth, cap),
        time_to_target(lambda: Ours(bench, 100, 200), model, truth, cap),
        time_to_target(lambda: PyCMA(bench, None, 10), model, truth, cap),
        time_to_target(lambda: Evosax(bench, "CMA_ES", popsize, 100), model, truth, cap),
        time_to_target(lambda: Evosax(bench, "SNES", popsize, 100), model, truth, cap),
    ]
    return out


def section_long(opts) -> dict:
    gens = opts.long_generations
    log(f"long: fit() paper horse neural pop 500 x {gens} generations in a child process")
    cmd = [sys.executable, str(Path(__file__).resolve()), "--task-long", str(gens)]
    t = now()
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        log(proc.stderr[-3000:])
        return {"error": proc.stderr[-3000:]}
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    res["process_wall_s"] = now() - t
    log(
        f"  fit {res['fit_wall_s']:.1f} s, RSS start/middle/end "
        f"{res['rss_start_mb']:.0f}/{res['rss_middle_mb']:.0f}/{res['rss_end_mb']:.0f} MB, "
        f"peak {res['peak_rss_mb']:.0f} MB"
    )
    return res


def task_long(generations: int) -> None:
    """Child process: the paper's experiment through the public API, RSS sampled per chunk."""
    from activebonds.identify import fit
    from activebonds.identify.settings import FitSettings

    settings = FitSettings(
        markers=P.HORSE_MARKERS,
        frames=(0, 10),
        bonds="neural",
        population=500,
        generations=generations,
        seed=0,
        refine="none",  # the ES's speed: no refinement after it
    )
    samples = []
    rss_before = rss_mb()
    t0 = now()

    def progress(gen, total, best_rms):
        samples.append((gen, now() - t0, rss_mb(), best_rms))

    result = fit(P.EXAMPLES / "horse_limb.toml", P.HORSE_CSV, settings, progress=progress)
    wall = now() - t0
    mid = min(samples, key=lambda s: abs(s[0] - generations / 2))
    # RSS swings by tens of MB between chunks (allocator); the floor shows the trend
    tenth = max(1, len(samples) // 10)
    floor_first = min(s[2] for s in samples[:tenth])
    floor_last = min(s[2] for s in samples[-tenth:])
    print(
        json.dumps(
            {
                "generations": generations,
                "population": 500,
                "chunk": settings.chunk,
                "fit_wall_s": wall,
                "first_chunk_done_s": samples[0][1],
                "steady_gens_per_s": (samples[-1][0] - samples[0][0])
                / max(samples[-1][1] - samples[0][1], 1e-9),
                "rss_before_fit_mb": rss_before,
                "rss_start_mb": samples[0][2],
                "rss_middle_mb": mid[2],
                "rss_end_mb": samples[-1][2],
                "rss_growth_mb": samples[-1][2] - samples[0][2],
                "rss_floor_first_tenth_mb": floor_first,
                "rss_floor_last_tenth_mb": floor_last,
                "rss_floor_growth_mb": floor_last - floor_first,
                "rss_max_after_first_chunk_mb": max(s[2] for s in samples),
                "peak_rss_mb": peak_rss_mb(),
                "best_rms_mm": result.rms_mm,
                "status": result.status,
                "samples": [(g, round(t, 3), round(r, 1)) for g, t, r, _ in samples][
                    :: max(1, len(samples) // 50)
                ],
            }
        )
    )


# ---------------------------------------------------------------------------------------------
# report


def environment() -> dict:
    def sh(cmd):
        try:
            return subprocess.run(cmd, capture_output=True, text=True, check=False).stdout.strip()
        except OSError:
            return ""

    cpu = ""
    for line in sh(["lscpu"]).splitlines():
        if line.startswith("Model name:"):
            cpu = line.split(":", 1)[1].strip()
    versions = {}
    for name in ("jax", "jaxlib", "numpy", "cma", "evosax", "flax"):
        try:
            versions[name] = __import__(name).__version__
        except Exception:  # noqa: BLE001
            from importlib.metadata import version

            try:
                versions[name] = version(name)
            except Exception:  # noqa: BLE001
                versions[name] = None
    repo = HERE.parent
    return {
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "versions": versions,
        "git_commit": sh(["git", "-C", str(repo), "rev-parse", "--short", "HEAD"]),
        "git_dirty_package": bool(sh(["git", "-C", str(repo), "status", "--porcelain", "src"])),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "loadavg_start": os.getloadavg(),
    }


def _f(x, digits=1):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if abs(x) >= 10000:
        return f"{x:,.0f}"
    return f"{x:.{digits}f}"


def print_report(report: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=160)
    env = report["environment"]
    console.print(
        f"[bold]activebonds ES benchmarks[/bold]  {env['date']}  {env['cpu']} x{env['cores']}  "
        f"jax {env['versions'].get('jax')}  commit {env['git_commit']}"
        f"{' (package modified)' if env['git_dirty_package'] else ''}  mode "
        f"{'quick' if report['quick'] else 'full'}  load average "
        f"{env['loadavg_start'][0]:.1f} -> {env.get('loadavg_end', [float('nan')])[0]:.1f}"
    )
    t = Table(title="Throughput (steady state; compile reported apart)")
    for col, just in (
        ("section", "left"),
        ("configuration", "left"),
        ("optimizer", "left"),
        ("P/B/G", "right"),
        ("S x H", "right"),
        ("pop", "right"),
        ("chunk", "right"),
        ("gen/s", "right"),
        ("evals/s", "right"),
        ("compile s", "right"),
        ("1st call +s", "right"),
        ("note", "left"),
    ):
        t.add_column(col, justify=just)
    for r in report.get("configs", []):
        t.add_row(
            r["section"],
            r["config"],
            r["optimizer"],
            f"{r['particles']}/{r['bonds']}/{r['genes']}",
            f"{r['starts']}x{r['horizon']}",
            str(r["population"]),
            str(r.get("block", "")),
            _f(r["gens_per_s"]),
            _f(r["evals_per_s"], 0),
            _f(r["compile_s"], 2),
            _f(r["first_call_extra_s"], 2),
            r.get("note", ""),
        )
    console.print(t)

    pairs = report.get("numpy", []) + report.get("peers", {}).get("pairs", [])
    if pairs:
        t = Table(title="Ours vs baselines, measured pair by pair (alternating; median ratio)")
        for col in (
            "baseline",
            "config",
            "pop",
            "ours gen/s",
            "its gen/s",
            "ours/it gen/s",
            "ours/it evals/s",
            "per-pair ratios",
        ):
            t.add_column(col, justify="left" if col in ("baseline", "config") else "right")
        for p in pairs:
            t.add_row(
                p["b"],
                p["config"],
                str(p["population"]),
                _f(p["a_gens_per_s"]),
                _f(p["b_gens_per_s"]),
                f"{p['gens_ratio']:.2f}x",
                f"{p['evals_ratio']:.2f}x",
                " ".join(f"{x:.2f}" for x in p["gens_ratios"]),
            )
        console.print(t)

    if report.get("ttt"):
        t = Table(title="Time to target: synthetic triangle, every parameter within 1 % of truth")
        for col in (
            "optimizer",
            "pop",
            "reached",
            "wall s (with compile)",
            "wall s (without)",
            "compile s",
            "generations",
            "evaluations",
            "max rel err",
        ):
            t.add_column(col, justify="left" if col == "optimizer" else "right")
        for r in report["ttt"]:
            t.add_row(
                r["optimizer"],
                str(r["population"]),
                "yes" if r["reached"] else "NOT reached",
                _f(r["wall_s"], 2),
                _f(r["wall_without_compile_s"], 2),
                _f(r["compile_s"], 2),
                f"{r['generations']:,}",
                f"{r['evaluations']:,}",
                f"{r['max_rel_error']:.1e}",
            )
        console.print(t)

    long = report.get("long")
    if long and "error" not in long:
        what = (
            "paper experiment end to end (fit API, compile included)"
            if long["generations"] >= 50_000
            else "long run (fit API, compile included)"
        )
        console.print(
            f"[bold]{what}[/bold]: pop {long['population']} x {long['generations']:,} generations "
            f"in {long['fit_wall_s']:.1f} s (first chunk done at {long['first_chunk_done_s']:.1f} s; "
            f"steady {long['steady_gens_per_s']:.0f} gen/s); RSS before fit "
            f"{long['rss_before_fit_mb']:.0f} MB, start/middle/end "
            f"{long['rss_start_mb']:.0f}/{long['rss_middle_mb']:.0f}/{long['rss_end_mb']:.0f} MB "
            f"(end - start {long['rss_growth_mb']:+.1f} MB; floor of first/last tenth "
            f"{long['rss_floor_first_tenth_mb']:.0f}/{long['rss_floor_last_tenth_mb']:.0f} MB, "
            f"{long['rss_floor_growth_mb']:+.1f} MB; max after first chunk "
            f"{long['rss_max_after_first_chunk_mb']:.0f} MB), peak {long['peak_rss_mb']:.0f} MB; "
            f"best RMS {long['best_rms_mm']:.2f} mm"
        )
    elif long:
        console.print(f"[red]long run failed[/red]: {long['error'][-500:]}")
    console.print(
        f"benchmark process: peak RSS {report['peak_rss_mb']:.0f} MB, "
        f"total {report['total_s']:.0f} s"
    )


SECTIONS = ("paper", "scale", "numpy", "peers", "ttt", "long")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="short measurements (~3 min)")
    ap.add_argument("--json", type=Path, help="write every number to this JSON file")
    ap.add_argument("--only", help=f"comma-separated sections of {','.join(SECTIONS)}")
    ap.add_argument("--task-long", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.task_long:
        task_long(args.task_long)
        return 0
    only = set(args.only.split(",")) if args.only else set(SECTIONS)
    unknown = only - set(SECTIONS)
    if unknown:
        ap.error(f"unknown sections: {', '.join(sorted(unknown))}")

    q = args.quick
    opts = argparse.Namespace(
        quick=q,
        min_s=0.4 if q else 2.0,
        min_calls=2 if q else 3,
        pair_s=0.4 if q else 1.0,
        repeats=2 if q else 5,
        ttt_cap=30.0 if q else 120.0,
        long_generations=3000 if q else 50_000,
    )
    started = now()
    report: dict = {"quick": q, "environment": environment(), "configs": []}
    if "paper" in only:
        report["configs"] += section_paper(opts)
    if "scale" in only:
        report["configs"] += section_scale(opts)
    if "numpy" in only:
        report["numpy"] = section_numpy(opts)
    if "peers" in only:
        peers = section_peers(opts)
        report["peers"] = {"pairs": peers["pairs"]}
        report["configs"] += peers["rows"]
    if "ttt" in only:
        report["ttt"] = section_ttt(opts)
    if "long" in only:
        report["long"] = section_long(opts)
    report["environment"]["loadavg_end"] = os.getloadavg()
    report["peak_rss_mb"] = peak_rss_mb()
    report["total_s"] = now() - started
    print_report(report)
    if args.json:
        args.json.write_text(json.dumps(report, indent=1, default=float) + "\n")
        log(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
