"""Recovery of a hopper simulated by an independent fine integrator (issue 24, contact).

    python scripts/hopper_recovery.py [--noise-mm 0,0.5] [--seed 0] [--cost shooting]
                                      [--horizon 10] [--substeps 20] [--integrator verlet]
                                      [--init uniform] [--population 100] [--generations 1000]
                                      [--json out.json]

The truth (``tests/hopper_truth.py``): a body (2 kg, fixed in the model) and a foot joined by
a viscoelastic leg, gravity, both against the ground plane (contact stiffness, damping,
height, smooth Coulomb friction), semi-implicit Euler at 1e-5 s sampled at 200 Hz for 2.5 s
(501 frames): it lands on its foot, slides, sticks, tips over and bounces on its body. The
model file has the foot mass, the leg's stiffness, rest length and damping and the ground's
height, stiffness, damping and friction free (8 genes) from wrong starts. Each row is one
``fit`` with the options given (default: the recommended command for real data, without
``--init lsq``, which contact bonds do not enter), and prints the relative error of every
parameter and how the refinement's stages ended.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import activebonds  # noqa: E402
import hopper_truth  # noqa: E402
from activebonds.model import loads_model  # noqa: E402

GENES = {  # gene name -> the truth's key
    "mass:foot.mass": "foot_mass",
    "type:leg.stiffness": "leg.stiffness",
    "type:leg.rest_length": "leg.rest_length",
    "type:leg.damping": "leg.damping",
    "type:ground.height": "ground.height",
    "type:ground.stiffness": "ground.stiffness",
    "type:ground.damping": "ground.damping",
    "type:ground.friction": "ground.friction",
}


def errors(model, genome, truth=hopper_truth.TRUTH) -> dict[str, float]:
    """{truth key: relative error} of a fitted genome."""
    nat = model.layout.natural(np.asarray(genome))
    by_name = {g.name: float(v) for g, v in zip(model.layout.genes, nat, strict=True)}
    return {key: (by_name[gene] - truth[key]) / truth[key] for gene, key in GENES.items()}


def run(noise_mm: float = 0.0, seed: int = 0, **options) -> dict:
    truth = hopper_truth.hopper()
    model = loads_model(truth.model_toml("start"), "hopper")
    data = truth.trajectory(noise_mm, seed)
    started = time.time()
    res = activebonds.fit(model, data, seed=seed, **options)
    seconds = time.time() - started
    for line in res.lines():
        print("  " + line, file=sys.stderr)
    return {
        "noise_mm": noise_mm,
        "seed": seed,
        "options": options,
        "seconds": round(seconds, 1),
        "errors": errors(model, res.genome),
        "search_errors": errors(model, res.es_genome if res.es_genome is not None else res.genome),
        "stages": [s.record() for s in res.refinement],
    }


def main(argv=None) -> int:
    from activebonds.runtime import fast_cpu_flags

    fast_cpu_flags()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise-mm", default="0,0.5")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cost", default="shooting")
    ap.add_argument("--horizon", default="10")
    ap.add_argument("--substeps", type=int, default=20)
    ap.add_argument("--integrator", default="verlet")
    ap.add_argument("--init", default="uniform")
    ap.add_argument("--population", type=int, default=100)
    ap.add_argument("--generations", type=int, default=1000)
    ap.add_argument("--refine", default="lm")
    ap.add_argument("--smooth", type=int, default=0)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    options = dict(
        cost=args.cost,
        horizon=tuple(int(h) for h in args.horizon.split(",")),
        substeps=args.substeps,
        integrator=args.integrator,
        init=args.init,
        population=args.population,
        generations=args.generations,
        refine=args.refine,
        smooth=args.smooth,
    )
    rows = []
    for noise in (float(s) for s in args.noise_mm.split(",")):
        row = run(noise, args.seed, **options)
        rows.append(row)
        for s in row["stages"]:
            print(
                f"  stage H={s['horizon']} {s['cost']}: {s['message']} ({s['steps']} steps, "
                f"{s['start_rms_mm']:.4g} -> {s['end_rms_mm']:.4g} mm, {s['seconds']:.0f} s)",
                file=sys.stderr,
            )
        print(f"noise {noise} mm: {row['seconds']} s", file=sys.stderr)
        search = ", ".join(f"{k} {100 * v:+.1f} %" for k, v in row["search_errors"].items())
        print(f"  the search's result: {search}", file=sys.stderr)
    print("| parameter | " + " | ".join(f"noise {r['noise_mm']:g} mm" for r in rows) + " |")
    print("|---|" + "---|" * len(rows))
    for key in rows[0]["errors"]:
        print(f"| {key} | " + " | ".join(f"{100 * r['errors'][key]:+.2f} %" for r in rows) + " |")
    print("| seconds | " + " | ".join(f"{r['seconds']:.0f}" for r in rows) + " |")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
