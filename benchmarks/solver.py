"""The one-step refinement of a 414-gene spring body on the bundled human walk: the sine
transform's Levenberg-Marquardt (the old solver) against the active set with NL2SOL's model.

    python benchmarks/solver.py [--quick] [--steps 500] [--old-steps N] [--substeps 2]
                                [--start lsq|model] [--json out.json]

The case: :func:`body_model.body_model_toml` on the REAL walk (``activebonds datasets
human-walk``: 41 markers, 151 frames, 60 Hz), each marker a particle bonded to its 6 nearest
at frame 0 (138 spring-dampers, 414 genes, every one bounded). The stage is the one
``activebonds fit --refine lm`` runs after the search (the restart cost at horizon 1, the
settings' ``--substeps`` Euler substeps), from the exact one-step least squares at one
substep (``--start lsq``, the search's ``--init lsq`` individual: many genes on their
bounds) or from the model file's values (``--start model``). Each solver runs on a
Refinement of its own in this process (its programs compiled inside its time), the old at
most ``--old-steps`` steps (default ``--steps``), the new at most ``--steps``; the table gives
each one's final objective (m^2), RMS, steps, seconds and message, and the new/old ratios.
``--quick``: 50 steps each.

Measured (2 shared cores, loaded), ``--steps 20``, 2 substeps, start lsq: old 0.035602 m^2
(2.4141 mm) in 210.8 s, new 0.035333 m^2 (2.4050 mm) in 215.5 s (ratios 0.9925, 1.02): the
same steps cost the same (the Jacobian dominates), the new ones lower the cost 2.3 times as
much (0.00047 against 0.00020 m^2 from 0.035805).

500 steps, 1 substep (the one-step cost ``auto`` refines on), 2026-12-07, other jobs on the
machine (``--steps 500 --substeps 1 [--start model] --json ...``: docs/results/solver_*.json):

* start lsq (``solver_lsq_start.json``; the crawl ``auto`` met: the refinement starts at the
  exact optimum, which it cannot improve): old 0.0357217 m^2 after 174 steps, 216.3 s,
  stopped as its damping grew without bound; new 0.0357217 m^2 in 2 steps, 5.4 s,
  converged: the same cost in 0.025 of the time;
* start model (``solver_model_start.json``; far from the optimum): old 0.0357221 m^2 at its
  500-step limit, 960.0 s; new 0.0357226 m^2 at the same limit, 777.4 s (objective ratio
  1.00002, time 0.81): both end within 3e-5 of the exact optimum's 0.0357217, the new one no
  faster to the end there.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def setup(substeps: int, start: str):
    import jax

    jax.config.update("jax_enable_x64", True)
    from activebonds.identify.costs.windows import make_windows
    from activebonds.identify.problem import identification
    from activebonds.identify.settings import FitSettings
    from activebonds.identify.solvers.lsq import least_squares
    from activebonds.model import loads_model
    from body_model import body_model_toml, walk

    traj = walk()
    model = loads_model(body_model_toml(traj), "<body>")
    settings = FitSettings(horizon=(1,), cost="restart", refine="lm", substeps=substeps)
    ident = identification(model, traj, settings)
    if start == "lsq":
        genome = least_squares(ident.model, make_windows(traj.positions, traj.mask, traj.dt, 1))
        genome = np.asarray(genome.genome, np.float64)
    else:
        genome = np.asarray(ident.model.layout.initial(), np.float64)
    return ident, settings, genome


def run(ident, settings, genome, steps: int, bounds: str) -> dict:
    from activebonds.identify.solvers.refine import Refinement

    t = time.perf_counter()
    refinement = Refinement(ident, settings, bounds=bounds)
    stage = refinement.stage(1, genome, max_steps=steps)
    seconds = time.perf_counter() - t
    print(f"  {bounds}: {stage.steps} steps, {seconds:.1f} s: {stage.message}", file=sys.stderr)
    g = np.asarray(stage.genome)
    lo, hi = np.asarray(ident.problem.lower), np.asarray(ident.problem.upper)
    near = np.minimum(g - lo, hi - g) <= 0.01 * (hi - lo)
    return {
        "bounds": bounds,
        "objective_m2": stage.end_objective,
        "start_objective_m2": stage.start_objective,
        "rms_mm": stage.end_rms_mm,
        "start_rms_mm": stage.start_rms_mm,
        "steps": stage.steps,
        "seconds": round(seconds, 2),
        "accepted": stage.accepted,
        "message": stage.message,
        "genes_within_1pct_of_a_bound": int(np.sum(near)),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="50 steps each")
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--old-steps", type=int, default=None)
    ap.add_argument("--substeps", type=int, default=2)
    ap.add_argument("--start", choices=("lsq", "model"), default="lsq")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    steps = 50 if args.quick else args.steps
    old_steps = steps if args.old_steps is None or args.quick else args.old_steps
    ident, settings, genome = setup(args.substeps, args.start)
    new = run(ident, settings, genome, steps, "active")
    old = run(ident, settings, genome, old_steps, "sine")
    rows = [("old (sine transform)", old), ("new (active set, hybrid)", new)]
    print(
        f"one-step refinement, 414-gene spring body on the walk, {args.substeps} substeps, "
        f"start {args.start}"
    )
    print(f"{'solver':26} {'objective m^2':>14} {'RMS mm':>9} {'steps':>6} {'seconds':>8}  message")
    for name, r in rows:
        print(
            f"{name:26} {r['objective_m2']:14.6g} {r['rms_mm']:9.5g} {r['steps']:6d} "
            f"{r['seconds']:8.1f}  {r['message']}"
        )
    ratio = {
        "objective_new_over_old": new["objective_m2"] / old["objective_m2"],
        "seconds_new_over_old": new["seconds"] / old["seconds"],
    }
    print(
        f"new / old: objective {ratio['objective_new_over_old']:.6g}, "
        f"time {ratio['seconds_new_over_old']:.3g}"
    )
    if args.json:
        record = {"args": vars(args), "old": old, "new": new, **ratio}
        Path(args.json).write_text(json.dumps(record, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
