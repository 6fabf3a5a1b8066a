"""The horse with hooves on the ground against the internal-only model, on held-out frames.

    python scripts/horse_ground.py [--population 200] [--generations 5000] [--seed 0]
                                   [--gait trot|walk|both] [--json out.json]

For each gait of the bundled VHDC horse (Horse1_M1 trot1 and walk1, all 7 markers), two
models are fitted on frames 0-299 with the paper's ES and the one-step cost, and judged on
frames 300-599 (never seen by the fit):

* ``ground``: examples/horse_trot_ground.toml (gravity, a contact per hoof against the ground
  plane with the treadmill belt's velocity, unary anchors on head, withers and sacrum, leg
  triangles, masses free as ratios of 500 kg). For the walk the belt velocity is measured the
  same way on the walk (median x velocity of the hooves below 2 cm) and set in the model.
* ``internal``: the same binary bonds and masses without gravity, contacts or anchors (every
  force internal: momentum is conserved).

Printed per gait and model: held-out one-step RMS (all markers, and per marker), free-run RMS
and frames within 50 mm (median of 10 starts, report.metrics), beside the zero-force
predictor and the internal-force floor (the lowest one-step RMS any internal-force model can
reach on those frames: exact, minimised over the mass ratios).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "src" / "activebonds" / "datasets" / "horse_vhdc"
MODEL = ROOT / "src" / "activebonds" / "examples" / "horse_trot_ground.toml"
GAITS = {"trot": "Horse1_M1_trot1_kinematics.csv", "walk": "Horse1_M1_walk1_kinematics.csv"}
FIT, TEST = (0, 300), (300, 600)
DECADES = 6.0  # the floor's mass search keeps each ratio to the first marker within 10^+-6


def belt_velocity(traj) -> float:
    """Median x velocity of the hooves while below 2 cm (in stance on the belt)."""
    x = traj.positions
    v = np.diff(x, axis=0) * traj.rate
    out = []
    for name in ("HFL", "HFR", "HHL", "HHR"):
        i = traj.markers.index(name)
        stance = x[1:, i, 2] < 0.02
        out.append(v[stance, i, 0])
    return float(np.median(np.concatenate(out)))


def models(belt: float):
    from activebonds.model import build, load_model

    ground = load_model(MODEL)
    bonds = []
    for b in ground.spec.bond:
        if b.kind == "contact":
            b = b.model_copy(update={"surface_velocity": [belt, 0.0, 0.0]})
        bonds.append(b)
    ground = build(ground.spec.model_copy(update={"bond": bonds}))
    internal_bonds = [b for b in ground.spec.bond if b.kind == "binary"]
    internal = build(
        ground.spec.model_copy(
            update={"bond": internal_bonds, "gravity": None, "name": "horse_trot_internal"}
        )
    )
    return {"ground": ground, "internal": internal}


def per_marker_rms(model, traj) -> tuple[float, np.ndarray]:
    from activebonds.identify.judge.predictions import one_step

    pred = one_step(model, traj.positions, traj.dt, 1, "euler")
    err2 = np.sum((pred - traj.positions) ** 2, axis=-1)  # [F, P], NaN where not predicted
    ok = np.isfinite(err2)
    total = float(np.sqrt(err2[ok].mean()) * 1000.0)
    each = np.array([np.sqrt(err2[ok[:, p], p].mean()) * 1000.0 for p in range(err2.shape[1])])
    return total, each


def zero_force_per_marker(traj) -> tuple[float, np.ndarray]:
    x = traj.positions
    pred = np.full_like(x, np.nan)
    pred[2:] = 2 * x[1:-1] - x[:-2]
    err2 = np.sum((pred - x) ** 2, axis=-1)
    ok = np.isfinite(err2)
    each = np.array([np.sqrt(err2[ok[:, p], p].mean()) * 1000.0 for p in range(err2.shape[1])])
    return float(np.sqrt(err2[ok].mean()) * 1000.0), each


def internal_floor(traj) -> tuple[float, list[float]]:
    """The momentum floor (linear and angular) minimised over the mass ratios: Nelder-Mead
    over log10 ratios to the first marker, each within +-DECADES (a tanh map), from equal
    masses, from the model file's masses and from each marker made 1000x heavier, then once
    more from the best point. A local search: an upper bound of the infimum over masses."""
    from activebonds.identify.judge.baselines import momentum_floor_rms_mm

    def masses(z):
        return 10.0 ** np.concatenate([[0.0], DECADES * np.tanh(z)])

    def floor(z):
        return momentum_floor_rms_mm(traj.positions, traj.mask, traj.dt, masses(z))

    p = traj.n_markers
    file_masses = np.array([40.0, 150.0, 150.0, 40.0, 40.0, 40.0, 40.0])[:p]
    starts = [np.ones(p), file_masses] + [np.where(np.arange(p) == k, 1e3, 1.0) for k in range(p)]
    best = (np.inf, None)
    for m0 in starts + [None]:
        if m0 is None:
            z0 = best[1]
        else:
            lm = np.log10(m0 / m0[0])[1:]
            z0 = np.arctanh(np.clip(lm / DECADES, -0.999, 0.999))
        res = minimize(floor, z0, method="Nelder-Mead", options={"maxfev": 400})
        if res.fun < best[0]:
            best = (float(res.fun), res.x)
    m = masses(best[1])
    return best[0], [float(v) for v in 500.0 * m / m.sum()]


def run_gait(gait: str, args) -> dict:
    from activebonds import fit, read_trajectory
    from activebonds.identify.judge.metrics import free_run_metrics, zero_force_metrics

    traj = read_trajectory(DATA / GAITS[gait])
    belt = belt_velocity(traj)
    held = traj.window(*TEST)
    out = {"gait": gait, "belt_velocity": belt, "markers": list(traj.markers), "models": {}}
    zf_total, zf_each = zero_force_per_marker(held)
    zf_free = zero_force_metrics(held)
    out["zero_force"] = {
        "one_step_rms_mm": zf_total,
        "per_marker_mm": zf_each.tolist(),
        "free_run_rms_mm": zf_free.free_run_rms_mm,
        "frames_within_50mm": zf_free.median_frames_within,
    }
    floor, floor_masses = internal_floor(held)
    out["internal_floor_mm"] = floor
    out["internal_floor_masses_kg"] = floor_masses
    for name, model in models(belt).items():
        t0 = time.time()
        res = fit(
            model,
            traj,
            frames=FIT,
            population=args.population,
            generations=args.generations,
            seed=args.seed,
            refine="none",  # the ES's one-step fit, as documented
        )
        total, each = per_marker_rms(res.model, held)
        free = free_run_metrics(res.model, held, offset=TEST[0] - FIT[0])
        fitted = free_run_metrics(res.model, traj.window(*FIT))
        out["models"][name] = {
            "fit_rms_mm": res.rms_mm,
            "fit_seconds": time.time() - t0,
            "held_out_one_step_rms_mm": total,
            "per_marker_mm": each.tolist(),
            "held_out_free_run_rms_mm": free.free_run_rms_mm,
            "held_out_frames_within_50mm": free.median_frames_within,
            "held_out_frames_within_censored": free.median_censored,
            "fit_window_frames_within_50mm": fitted.median_frames_within,
            "masses_kg": [float(m) for m in np.asarray(res.model.params.mass)],
        }
        print(f"[{gait}] {name}: fit {res.rms_mm:.3f} mm, held-out {total:.3f} mm", file=sys.stderr)
    return out


def table(result: dict) -> str:
    names = result["markers"]
    head = (
        "| predictor | held-out one-step RMS | "
        + " | ".join(names)
        + " | free-run RMS | frames within 50 mm |"
    )
    lines = [head, "|" + "---|" * (len(names) + 4)]

    def row(label, total, each, free, within):
        cells = " | ".join(f"{e:.2f}" for e in each)
        return f"| {label} | {total:.3f} | {cells} | {free:.0f} | {within:g} |"

    for name, m in result["models"].items():
        lines.append(
            row(
                f"{name} model (fit {m['fit_rms_mm']:.3f})",
                m["held_out_one_step_rms_mm"],
                m["per_marker_mm"],
                m["held_out_free_run_rms_mm"],
                m["held_out_frames_within_50mm"],
            )
        )
    z = result["zero_force"]
    lines.append(
        row("zero force", z["one_step_rms_mm"], z["per_marker_mm"], z["free_run_rms_mm"],
            z["frames_within_50mm"])
    )  # fmt: skip
    lines.append(f"| internal-force floor (best mass ratios) | {result['internal_floor_mm']:.3f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    from activebonds.runtime import fast_cpu_flags

    fast_cpu_flags()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--population", type=int, default=200)
    ap.add_argument("--generations", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--gait", choices=["trot", "walk", "both"], default="both")
    ap.add_argument("--json", type=Path)
    ap.add_argument(
        "--floor-only",
        action="store_true",
        help="recompute only the internal-force floors of the --json file's results, in place",
    )
    args = ap.parse_args(argv)
    gaits = ["trot", "walk"] if args.gait == "both" else [args.gait]
    if args.floor_only:
        from activebonds import read_trajectory

        results = json.loads(args.json.read_text())
        for r in results:
            held = read_trajectory(DATA / GAITS[r["gait"]]).window(*TEST)
            r["internal_floor_mm"], r["internal_floor_masses_kg"] = internal_floor(held)
            r["internal_floor_masses_kg"] = [float(m) for m in r["internal_floor_masses_kg"]]
    else:
        results = [run_gait(g, args) for g in gaits]
    for r in results:
        print(
            f"\n{r['gait']} (belt {r['belt_velocity']:.3f} m/s), fit frames 0-299, held out 300-599:"
        )
        print(table(r))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
