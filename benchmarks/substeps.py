"""Substeps written out or run as a loop: each program of a shooting stage and of the ES,
traced, compiled and run both ways in one process.

    python benchmarks/substeps.py [--case tetra] [--json out.json]

``physics.integrate.advance`` writes a frame's substeps out in the program (up to
``UNROLLED``) where its caller asks (``unroll=True``) and runs them as a loop otherwise. Per
program and form: seconds to trace (Python), to compile (XLA) and to run (the median of 5,
after a first run), on the case of ``benchmarks/shooting.py`` (default: MuJoCo's tendon
tetrahedron, 801 frames, H = 20, 5 Verlet substeps, from the one-step optimum). Programs: the
population's cost (100 genomes, vmapped; the ES's) at one frame and at H frames; the restart
residuals at H and their Jacobian over the parameters (the shooting stage's warm start); the
shooting residuals and the normal equations by window (the structured path); the Jacobian
over every unknown (the dense path's forward mode). JAX's persistent cache is off.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))


def _time(fn, *args) -> dict:
    import jax

    t = time.perf_counter()
    traced = fn.trace(*args)
    trace = time.perf_counter() - t
    t = time.perf_counter()
    compiled = traced.lower().compile()
    compile_ = time.perf_counter() - t
    jax.block_until_ready(compiled(*args))
    runs = []
    for _ in range(5):
        t = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        runs.append(time.perf_counter() - t)
    return {
        "trace_s": round(trace, 3),
        "compile_s": round(compile_, 3),
        "run_s": round(statistics.median(runs), 5),
    }


def programs(name: str):
    """(name, build(unroll) -> (jitted function, arguments)) of every program measured."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    from jax.flatten_util import ravel_pytree

    from activebonds.identify.costs.shooting import (
        frame_states,
        make_shooting,
        shooting_windows,
        start_states,
    )
    from activebonds.identify.costs.windows import make_cost, make_residuals, make_windows
    from activebonds.identify.problem import identification
    from activebonds.identify.settings import FitSettings
    from activebonds.identify.solvers.lsq import least_squares
    from activebonds.identify.solvers.refine import Bounded
    from activebonds.identify.solvers.shooting_normal import make_normal
    from shooting import case

    model, traj, horizon, substeps, method = case(name)
    genome = least_squares(model, make_windows(traj.positions, traj.mask, traj.dt, 1)).genome
    settings = FitSettings(
        horizon=(horizon,), cost="shooting", substeps=substeps, integrator=method
    )
    problem = identification(model, traj, settings).problem
    bounded = Bounded(problem.lower, problem.upper)
    u = jnp.asarray(bounded.from_genome(np.asarray(genome)))
    g = jnp.asarray(genome)
    rng = np.random.default_rng(0)
    population = g[None] * (1 + 0.01 * jnp.asarray(rng.normal(size=(100, g.size))))
    windows = {h: make_windows(traj.positions, traj.mask, traj.dt, h) for h in (1, horizon)}
    shots = shooting_windows(traj.positions, traj.mask, traj.dt, horizon)
    x0, v0 = start_states(shots, [frame_states(traj.positions, traj.mask, traj.dt)])
    x0, v0 = jnp.asarray(x0), jnp.asarray(v0)
    k = x0.shape[0]
    states = jnp.concatenate([x0.reshape(k, -1), v0.reshape(k, -1)], axis=1)

    def population_cost(h):
        def build(unroll):
            cost = make_cost(model, windows[h], substeps, method, unroll=unroll)
            return jax.jit(jax.vmap(lambda x: cost(x)[0])), (population,)

        return build

    def restart(unroll):
        res = make_residuals(model, windows[horizon], substeps, method, unroll=unroll)
        return jax.jit(lambda x: res(bounded.to_genome(x))), (u,)

    def restart_jacobian(unroll):
        res = make_residuals(model, windows[horizon], substeps, method, unroll=unroll)
        return jax.jit(jax.jacfwd(lambda x: res(bounded.to_genome(x)).ravel())), (u,)

    def shooting(unroll):
        res, _ = make_shooting(model, shots, substeps, method, unroll=unroll)
        return jax.jit(lambda x, xs, vs: res(bounded.to_genome(x), (xs, vs))), (u, x0, v0)

    def normal(unroll):
        make = make_normal(model, shots, substeps, method, bounded.to_genome, unroll=unroll)
        return jax.jit(make), (u, states)

    def dense_jacobian(unroll):
        res, _ = make_shooting(model, shots, substeps, method, unroll=unroll)

        def flat(y):
            x, xs, vs = y
            return ravel_pytree(res(bounded.to_genome(x), (xs, vs)))[0]

        return jax.jit(jax.jacfwd(flat)), ((u, x0, v0),)

    meta = {"frames": int(traj.positions.shape[0]), "horizon": horizon, "substeps": substeps}
    return meta, [
        ("population cost, 1 frame (ES)", population_cost(1)),
        (f"population cost, {horizon} frames (ES)", population_cost(horizon)),
        (f"restart residuals, {horizon} frames", restart),
        ("restart Jacobian (warm start)", restart_jacobian),
        ("shooting residuals", shooting),
        ("normal equations by window (structured)", normal),
        ("Jacobian over every unknown (dense)", dense_jacobian),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", default="tetra")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    from activebonds.runtime import fast_cpu_flags

    fast_cpu_flags()
    import jax

    jax.config.update("jax_enable_x64", True)
    meta, built = programs(args.case)
    rows = []
    for label, build in built:
        row = {"program": label}
        for unroll in (True, False):
            fn, arguments = build(unroll)
            row["written out" if unroll else "loop"] = _time(fn, *arguments)
        rows.append(row)
        a, b = row["written out"], row["loop"]
        print(
            f"{label}: written out {a['trace_s']} / {a['compile_s']} / {a['run_s']} s, "
            f"loop {b['trace_s']} / {b['compile_s']} / {b['run_s']} s (trace / compile / run)",
            flush=True,
        )
    if args.json:
        args.json.write_text(json.dumps({"case": args.case, **meta, "programs": rows}, indent=1))


if __name__ == "__main__":
    main()
