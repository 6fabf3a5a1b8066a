"""Recovery of MuJoCo's tendon parameters: the one-step cost against multiple shooting (issue 12).

    python scripts/mujoco_recovery.py [--seeds 0] [--noise-mm 0,0.5] [--substeps 10]
                                      [--horizon 10] [--rate 100] [--seconds 2] [--trials 1]
                                      [--excitation 1] [--damping-scale 1] [--json out.json]

The truth comes from an independent simulator (``tests/mujoco_truth.py``): 4 free point
masses joined by 6 MuJoCo spatial tendons (stiffness, damping, springlength), no gravity or
contact, RK4 at 1e-4 s, sampled at 100 Hz for 2 s (201 frames). The model file has every
bond's stiffness, rest length and damping free (18 genes) with deliberately wrong starts;
masses fixed at the truth. Each row fits the same data two ways:

* ``one-step``: the paper's one-step cost, solved exactly (``--init lsq``: the linear least
  squares of (k, k l0, c) is the one-step optimum of this family, so no search can do better),
  then the ES for ``--generations`` (default 1: the optimum is already in the population);
* ``shooting`` (the recommended command): the same, then ``--refine lm --cost shooting
  --horizon H --substeps N --integrator verlet``.

Reported: the relative error of every stiffness, rest length and damping (max and median per
kind). With ``--noise-mm`` Gaussian noise (standard deviation per axis, mm) is added to the
markers, the same draw for both fits. ``--trials N`` records N starts of the same system
(a subject's trials) and fits them at once (``fit MODEL A B ...``).
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
import mujoco_truth  # noqa: E402
from activebonds.data import Trajectory  # noqa: E402
from activebonds.identify.judge.baselines import zero_force_rms_mm  # noqa: E402
from activebonds.model import loads_model  # noqa: E402

KINDS = ("stiffness", "rest_length", "damping")


def errors(model, genome, truth) -> dict:
    """{kind: [relative errors, bond order]}."""
    nat = model.layout.natural(np.asarray(genome))
    by_name = {g.name: v for g, v in zip(model.layout.genes, nat, strict=True)}
    out = {k: [] for k in KINDS}
    for bond in truth.bonds:
        i, j = bond.particles
        for kind in KINDS:
            got = by_name[f"type:b{i}{j}.{kind}"]
            want = getattr(bond, kind)
            out[kind].append(float(abs(got - want) / want))
    return out


def summary(errs: dict) -> dict:
    return {
        k: {"max_pct": 100 * max(v), "median_pct": 100 * float(np.median(v))}
        for k, v in errs.items()
    }


def noise_floor(model, truths, noise_mm: float, substeps: int, integrator: str) -> dict:
    """The Cramer-Rao bound: the smallest standard deviation any unbiased estimator can have
    for each parameter, from Gaussian marker noise of ``noise_mm`` (per axis) on these
    recordings, the unknowns being the parameters and every recording's start state (what
    shooting fits). Relative to the truth, per kind (max and median, per cent): a floor
    that no cost can beat, against which the fits' errors are read."""
    import jax
    import jax.numpy as jnp

    from activebonds.physics.integrate import rollout_states

    layout, topo = model.layout, model.topology
    genome = layout.initial()  # the truth model's values, in search space
    names = [g.name for g in layout.genes]
    blocks = []
    for truth in truths:
        n = truth.n_frames - 1
        dt = 1.0 / truth.rate

        def positions(y, n=n, dt=dt):
            g, x0, v0 = y
            xs, _ = rollout_states(layout.decode(g), topo, x0, v0, dt, n, substeps, integrator)
            return xs.ravel()

        y = (jnp.asarray(genome), jnp.asarray(truth.positions[0]), jnp.asarray(truth.velocities[0]))
        jac = jax.jacfwd(positions)(y)
        blocks.append([np.asarray(j).reshape(j.shape[0], -1) for j in jac])
    # one Fisher matrix over [genes, each recording's start state]
    n_g = len(genome)
    n_s = blocks[0][1].shape[1] + blocks[0][2].shape[1]
    fisher = np.zeros((n_g + n_s * len(blocks),) * 2)
    for r, (jg, jx, jv) in enumerate(blocks):
        cols = np.zeros((jg.shape[0], fisher.shape[0]))
        cols[:, :n_g] = jg
        cols[:, n_g + r * n_s : n_g + (r + 1) * n_s] = np.hstack([jx, jv])
        fisher += cols.T @ cols
    sigma = noise_mm / 1000.0
    cov = sigma**2 * np.linalg.inv(fisher)
    sd = np.sqrt(np.diag(cov)[:n_g])  # log genes: relative already; others: absolute
    rel = np.where(layout.log, sd, sd / np.abs(genome))
    out = {k: [] for k in KINDS}
    for name, r in zip(names, rel, strict=True):
        out[name.rsplit(".", 1)[1]].append(float(r))
    return summary(out)


def noisy(traj: Trajectory, noise_mm: float, seed: int) -> Trajectory:
    if noise_mm == 0:
        return traj
    rng = np.random.default_rng(1000 + seed)
    pos = traj.positions + rng.normal(0.0, noise_mm / 1000.0, traj.positions.shape)
    return Trajectory(
        positions=pos, markers=traj.markers, rate=traj.rate, mask=traj.mask, source=traj.source
    )


def one(seed: int, noise_mm: float, args) -> dict:
    truths = [
        mujoco_truth.tendon_system(
            n_particles=4,
            rate=args.rate,
            seconds=args.seconds,
            seed=seed,
            damping_scale=args.damping_scale,
            trial=trial,
            excitation=args.excitation,
        )
        for trial in range(args.trials)
    ]
    truth = truths[0]
    model = loads_model(truth.model_toml("start"), "mujoco")
    trajs = [noisy(t.trajectory(), noise_mm, seed + 7919 * i) for i, t in enumerate(truths)]
    traj = trajs[0] if len(trajs) == 1 else trajs  # several recordings are fitted at once
    base = dict(init="lsq", generations=args.generations, population=args.population, seed=seed)
    plain_only = dict(refine="none")  # the one-step optimum, no refinement
    t = time.time()
    plain = activebonds.fit(model, traj, **base, **plain_only)
    t_plain = time.time() - t
    t = time.time()
    shot = activebonds.fit(
        model,
        traj,
        **base,
        refine="lm",
        cost="shooting",
        horizon=tuple(args.horizon),
        substeps=args.substeps,
        integrator=args.integrator,
    )
    t_shot = time.time() - t
    row = {
        "seed": seed,
        "noise_mm": noise_mm,
        "noise_floor": noise_floor(
            loads_model(truth.model_toml("truth"), "mujoco"),
            truths,
            noise_mm,
            args.substeps,
            args.integrator,
        )
        if noise_mm
        else None,
        # the one-step fit's RMS beside the zero-force predictor (first recording; the
        # shooting stage's position RMS is in "stages")
        "zero_force_rms_mm": zero_force_rms_mm(trajs[0].positions, trajs[0].mask, trajs[0].dt),
        "one_step_rms_mm": plain.rms_mm,
        "one_step": summary(errors(model, plain.genome, truth)),
        "shooting": summary(errors(model, shot.genome, truth)),
        "one_step_seconds": round(t_plain, 1),
        "shooting_seconds": round(t_shot, 1),
        "stages": [{k: v for k, v in s.record().items() if k != "genome"} for s in shot.refinement],
    }
    print(
        json.dumps({k: row[k] for k in ("seed", "noise_mm", "noise_floor", "one_step", "shooting")})
    )
    return row


def _pct(x: float) -> str:
    if x >= 100:
        return f"{x:,.0f} %"
    return f"{x:.1f} %" if x >= 10 else (f"{x:.2f} %" if x >= 0.1 else f"{x:.3f} %")


def table(record: dict) -> str:
    """The markdown table of docs/experiments/shooting.md for a JSON record of this script."""
    lines = [
        "| seed | estimate | stiffness max / median | rest length max | damping max / median | time |",
        "|---|---|---|---|---|---|",
    ]
    for r in record["rows"]:
        for key, label, seconds in (
            ("noise_floor", "Cramér-Rao floor (1 s.d.)", None),
            ("one_step", "one-step optimum", r["one_step_seconds"]),
            ("shooting", "shooting", r["shooting_seconds"]),
        ):
            e = r.get(key)
            if not e:
                continue
            lines.append(
                f"| {r['seed']} | {label} | {_pct(e['stiffness']['max_pct'])} / "
                f"{_pct(e['stiffness']['median_pct'])} | {_pct(e['rest_length']['max_pct'])} | "
                f"{_pct(e['damping']['max_pct'])} / {_pct(e['damping']['median_pct'])} | "
                f"{'' if seconds is None else f'{seconds:.0f} s'} |"
            )
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--noise-mm", default="0,0.5")
    ap.add_argument("--substeps", type=int, default=10)
    ap.add_argument("--integrator", default="verlet")
    ap.add_argument("--horizon", default="10", help="comma-separated curriculum")
    ap.add_argument("--generations", type=int, default=1)
    ap.add_argument("--population", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--damping-scale", type=float, default=1.0, help="dampings x this")
    ap.add_argument("--rate", type=float, default=100.0, help="sample rate, Hz")
    ap.add_argument(
        "--trials",
        type=int,
        default=1,
        help="recordings of the system (other starts), fitted at once",
    )
    ap.add_argument(
        "--excitation", type=float, default=1.0, help="start perturbation and speed x this"
    )
    ap.add_argument("--json", type=Path)
    ap.add_argument("--table", type=Path, help="print the markdown table of this JSON and stop")
    args = ap.parse_args(argv)
    if args.table:
        print(table(json.loads(args.table.read_text())))
        return 0
    args.horizon = [int(h) for h in args.horizon.split(",")]
    rows = []
    for n in args.noise_mm.split(","):
        for seed in args.seeds.split(","):
            rows.append(one(int(seed), float(n), args))
            if args.json:  # after every row: a long run keeps what it measured
                record = {"args": vars(args) | {"json": str(args.json)}, "rows": rows}
                args.json.write_text(json.dumps(record, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
