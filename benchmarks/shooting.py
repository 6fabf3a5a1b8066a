"""Multiple shooting: the dense path (optimistix on the whole Jacobian) against the structured
path (normal equations by window, states eliminated), side by side in one run.

    python benchmarks/shooting.py [--cases tetra,horse7,walk,body300,body600]
                                  [--paths dense,structured] [--warm] [--trace]
                                  [--json out.json]

Each (case, path) runs in its own process, one after another, so its peak memory (RSS) is
its own, with JAX's persistent compilation cache off (every program compiled in the stage's
time); ``--warm`` also runs it twice more with a cache of its own and records the second
(``warm_seconds``: a repeated fit of the same shapes, the command line's default cache). One shooting stage from the same start (the one-step optimum, solved exactly) on
the same data; per path: the stage's seconds (the warm start on the restart cost, then the
shooting solve, compilation included) and its process's CPU seconds (every thread: on a
machine shared with other work, the figure that load does not inflate), its Levenberg-Marquardt steps, peak RSS, the final
objective and RMS; per case: the largest difference of a parameter between paths, relative
and in the structured fit's standard errors (its Gauss-Newton uncertainty, the states eliminated).
A dense path whose Jacobian alone would need more than ``--max-gb`` is not run: the record
says what it would need (forming it takes one forward pass per unknown over the whole
recording, QR-factored at every step).

Cases: ``tetra``, MuJoCo's tendon tetrahedron (4 particles, 6 tendons, 18 genes; RK4 at
1e-4 s) at 100 Hz for 8 s (801 frames), 0.5 mm noise, H = 20, 5 Verlet substeps (the design
of docs/experiments/shooting.md); ``horse7``, a 7-marker spring model of the bundled horse at trot
(600 frames); ``bodyN``, a 41-marker spring network of the bundled human walk's markers
(``body_model``: at least 100 bonds), simulated by our own integrator for N frames, 0.5 mm
noise; ``walk``, that model on the bundled human walk itself (151 frames, 60 Hz). The body
cases are fitted with 2 Verlet substeps (its stiffest spring at 60 Hz: omega h = 0.6).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT.parent / "tests"))
sys.path.insert(0, str(ROOT))

NOISE_MM = 0.5


def _noisy(traj, seed: int):
    from activebonds.data import Trajectory

    rng = np.random.default_rng(seed)
    pos = traj.positions + rng.normal(0.0, NOISE_MM / 1000.0, traj.positions.shape)
    return Trajectory(
        positions=pos, markers=traj.markers, rate=traj.rate, mask=traj.mask, source=traj.source
    )


def case(name: str):
    """(model, trajectory, horizon, substeps, integrator) of a case."""
    from activebonds.model import loads_model

    if name == "tetra":
        import mujoco_truth

        truth = mujoco_truth.tendon_system(n_particles=4, rate=100.0, seconds=8.0, seed=0)
        model = loads_model(truth.model_toml("start"), "mujoco")
        return model, _noisy(truth.trajectory(), 1000), 20, 5, "verlet"
    if name == "horse7":
        from body_model import horse_case

        model, traj = horse_case(600)
        return model, traj, 10, 5, "verlet"
    if name == "walk":
        from body_model import body_model_toml, walk

        traj = walk()
        return loads_model(body_model_toml(traj), "body"), traj, 10, 2, "verlet"
    if name.startswith("body"):
        from body_model import body_case

        model, traj = body_case(int(name[4:]))
        return model, _noisy(traj, 1001), 10, 2, "verlet"
    raise SystemExit(f"unknown case {name!r}")


def dense_bytes(model, traj, horizon: int) -> float:
    """The dense path's Jacobian (float64): residuals x (parameters + window states)."""
    n = traj.n_frames
    coords = traj.positions.shape[1] * traj.positions.shape[2]
    windows = max(1, -(-(n - 1) // horizon))
    unknowns = model.layout.n_genes + windows * 2 * coords
    residuals = n * coords + windows * 2 * coords
    return 8.0 * unknowns * residuals


def _traced(timeline: list) -> None:
    """Record the stage's parts (warm start, checks, the one-step stage instead) and every
    Levenberg-Marquardt solve (steps, message, seconds) in ``timeline``, each also printed to
    stderr as it ends, every 10th step's loss too (``--trace``: where a long stage goes)."""
    from activebonds.identify.costs.restart_cost import RestartCost
    from activebonds.identify.costs.shooting_cost import ShootingCost
    from activebonds.identify.solvers import refine, stage

    t0 = time.perf_counter()

    def note(entry):
        entry["at"] = round(time.perf_counter() - t0, 1)
        timeline.append(entry)
        print(f"[{entry['at']:8.1f} s] {entry}", file=sys.stderr, flush=True)

    solve = stage.levenberg_marquardt

    def traced_solve(*args, **kwargs):
        t, user = time.perf_counter(), kwargs.get("on_step")

        def on_step(steps, loss):
            if steps % 10 == 0:
                print(f"    step {steps}: loss {loss:.6g}", file=sys.stderr, flush=True)
            if user:
                user(steps, loss)

        out = solve(*args, **{**kwargs, "on_step": on_step})
        note({"solve": out[1], "message": out[2], "seconds": round(time.perf_counter() - t, 1)})
        return out

    stage.levenberg_marquardt = traced_solve
    parts = (
        (RestartCost, "stage", "restart"),
        (refine.Refinement, "versus_constant_velocity", "versus_constant_velocity"),
        (ShootingCost, "_one_step_instead", "one_step_instead"),
    )
    for owner, part, label in parts:
        method = getattr(owner, part)

        def traced(self, *args, _method=method, _part=label, **kwargs):
            t = time.perf_counter()
            out = _method(self, *args, **kwargs)
            said = getattr(out, "message", out)
            note({"part": _part, "seconds": round(time.perf_counter() - t, 1), "result": said})
            return out

        setattr(owner, part, traced)


def child(name: str, path: str) -> dict:
    from activebonds.runtime import fast_cpu_flags

    fast_cpu_flags()  # as the command line does, before JAX's first computation
    import jax

    from activebonds.runtime import compilation_cache

    compilation_cache()  # the parent's choice: off, or a folder of its own (--warm)

    from activebonds.identify.costs.windows import make_windows
    from activebonds.identify.problem import identification
    from activebonds.identify.settings import FitSettings
    from activebonds.identify.solvers.lsq import least_squares
    from activebonds.identify.solvers.refine import Refinement

    jax.config.update("jax_enable_x64", True)
    timeline: list = []
    if os.environ.get("SHOOTING_TRACE"):
        _traced(timeline)
    model, traj, horizon, substeps, integrator = case(name)
    settings = FitSettings(
        horizon=(horizon,), cost="shooting", refine="lm", substeps=substeps, integrator=integrator
    )
    ident = identification(model, traj, settings)
    start = least_squares(ident.model, make_windows(traj.positions, traj.mask, traj.dt, 1))
    t, cpu = time.perf_counter(), time.process_time()
    refinement = Refinement(ident, settings, solver=path)
    stage = refinement.stage(horizon, start.genome)
    seconds, cpu = time.perf_counter() - t, time.process_time() - cpu
    natural = ident.model.layout.natural(np.asarray(stage.genome))
    errors = None
    if path == "structured" and stage.cost == "shooting" and stage.accepted:
        from activebonds.identify.judge.uncertainty import estimate

        report = estimate(ident, settings, stage.genome, horizon, "shooting", refinement.states)
        errors = [e.std_error for e in report.estimates]
    return {
        "natural": [float(v) for v in natural],
        "std_errors": errors,
        "cost": stage.cost,
        "seconds": round(seconds, 2),
        "cpu_seconds": round(cpu, 2),
        "steps": stage.steps,
        "accepted": stage.accepted,
        "message": stage.message,
        "end_rms_mm": stage.end_rms_mm,
        "continuity_mm": stage.continuity_mm,
        "genome": stage.genome,
        "peak_rss_gb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 3),
        **({"timeline": timeline} if timeline else {}),
    }


def _run_child(name: str, path: str, cache: str, trace: bool = False) -> dict:
    """One (case, path) in its own process, JAX's persistent cache ``cache`` (a folder, or
    "off"); ``trace``: its timeline printed as it goes and kept in the result."""
    env = {**os.environ, "ACTIVEBONDS_CACHE": cache, **({"SHOOTING_TRACE": "1"} if trace else {})}
    out = subprocess.run(
        [sys.executable, __file__, "--child", name, path],
        stdout=subprocess.PIPE,
        stderr=None if trace else subprocess.PIPE,
        text=True,
        env=env,
    )
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("RESULT ")]
    if not line:
        return {"failed": (out.stderr or "see above").strip().splitlines()[-1:]}
    return json.loads(line[0][7:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default="tetra")
    parser.add_argument("--paths", default="dense,structured")
    parser.add_argument("--max-gb", type=float, default=0.5, help="largest dense Jacobian run")
    parser.add_argument("--json", type=Path)
    parser.add_argument(
        "--warm",
        action="store_true",
        help="also time each path with JAX's persistent cache warm (a repeated fit)",
    )
    parser.add_argument(
        "--trace",
        action="store_true",
        help="print where each stage's time goes (its parts and solves) and keep it in the JSON",
    )
    parser.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print("RESULT " + json.dumps(child(*args.child)))
        return
    record = {"noise_mm": NOISE_MM, "cases": {}}
    for name in args.cases.split(","):
        model, traj, horizon, substeps, integrator = case(name)
        row = {
            "frames": traj.n_frames,
            "markers": traj.positions.shape[1],
            "genes": model.layout.n_genes,
            "horizon": horizon,
            "substeps": substeps,
            "integrator": integrator,
            "dense_jacobian_gb": round(dense_bytes(model, traj, horizon) / 2**30, 3),
        }
        for path in args.paths.split(","):
            need = dense_bytes(model, traj, horizon) / 2**30
            if path == "dense" and need > args.max_gb:
                row[path] = {"skipped": f"its Jacobian alone needs {need:.1f} GB"}
                print(f"{name} {path}: skipped ({need:.1f} GB Jacobian)", flush=True)
                continue
            row[path] = _run_child(name, path, "off", args.trace)
            if args.warm and "seconds" in row[path]:  # a second run loads the first's programs
                with tempfile.TemporaryDirectory() as cache:
                    _run_child(name, path, cache)
                    warm = _run_child(name, path, cache)
                row[path]["warm_seconds"] = warm.get("seconds")
                row[path]["warm_cpu_seconds"] = warm.get("cpu_seconds")
                row[path]["warm_steps"] = warm.get("steps")
            hidden = ("genome", "natural", "std_errors", "timeline")
            shown = {k: v for k, v in row[path].items() if k not in hidden}
            print(f"{name} {path}: {shown}", flush=True)
        a, b = row.get("dense", {}), row.get("structured", {})
        if "genome" in a and "genome" in b:
            ga, gb = np.asarray(a["genome"]), np.asarray(b["genome"])
            row["max_rel_param_diff"] = float(np.max(np.abs(ga - gb) / np.abs(ga)))
            se = b.get("std_errors")
            if se and all(e is not None for e in se):  # in the structured fit's standard errors
                na, nb = np.asarray(a["natural"]), np.asarray(b["natural"])
                row["max_param_diff_sd"] = float(np.max(np.abs(na - nb) / np.asarray(se)))
            row["speedup"] = round(a["seconds"] / b["seconds"], 2)
            row["cpu_speedup"] = round(a["cpu_seconds"] / b["cpu_seconds"], 2)
            if a.get("warm_seconds") and b.get("warm_seconds"):
                row["warm_speedup"] = round(a["warm_seconds"] / b["warm_seconds"], 2)
                row["warm_cpu_speedup"] = round(a["warm_cpu_seconds"] / b["warm_cpu_seconds"], 2)
                print(
                    f"{name}: compilation cache warm, {row['warm_speedup']}x "
                    f"({row['warm_cpu_speedup']}x in CPU seconds)"
                )
            print(
                f"{name}: {row['speedup']}x ({row['cpu_speedup']}x in CPU seconds), max rel diff {row['max_rel_param_diff']:.2e}, "
                f"{row.get('max_param_diff_sd', float('nan')):.3g} standard deviations"
            )
        record["cases"][name] = row
        if args.json:  # after every case: a long run keeps what it measured
            args.json.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
