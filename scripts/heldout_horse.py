"""The horse's held-out one-step targets (issue 25): what the exact least squares reaches, what
``activebonds auto`` lost against it, and what ``auto`` gives now.

    python scripts/heldout_horse.py [--json docs/results/heldout_horse.json]
                                    [--auto DIR] [--gait trot|walk|both]

For each gait of the bundled VHDC horse (Horse1_M1 trot1 and walk1, all 7 markers), fitted on
frames 0-299 and judged on frames 300-599 (one-step RMS in mm, overall and per marker, beside
the zero-force predictor's):

1. ``exact``: every pair of markers (21 binary spring-dampers) and an anchor per marker (7
   unary spring-dampers), rest lengths and anchors free, by exact one-step least squares
   (identify/solvers/lsq.py), masses as examples/horse_trot_ground.toml's, with the issue's bounds
   (the 4.53 mm: stiffness and damping from 0, rest lengths to 3 times the largest distance,
   anchors 5 m about their means, gravity) and with the scaffold's (rest lengths to twice the
   largest distance, anchors two extents about their medians), and with the scaffold's
   masses (equal);
2. ``ablations``: the exact optimum (no ES, no contacts, no gravity) of the candidate models
   ``auto`` had and has, one change at a time: the neighbourhood candidates of the scaffold
   before this change (k nearest, near-rigid, Delaunay: no anchor), every candidate or the
   BIC's; the complete graph without anchors; with rest lengths and anchors fixed at their
   means over the fitted frames; BIC-pruned;
3. ``variants``: the 12 variants ``auto`` chooses among (identify/discover/structure_choice.py), each
   scored on the validation tail 240-299 after a fit on 0-239 (what the choice sees) and,
   for the record, refitted on 0-299 and judged on 300-599 (what the choice never sees);
4. with ``--auto DIR``: ``activebonds auto DATA --held-out 0.5 --out DIR/GAIT`` (run unless
   DIR/GAIT holds a finished run of it), its held-out evaluation (evaluation.json) and the
   kept model's free runs counted over the body markers alone (``evaluate --body
   Head,Withers,Sacrum``); the same of ``auto``'s own split (``--out DIR/GAIT-default``:
   fitted on 0-479, judged on 480-599).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GAITS = {"trot": "horse-trot", "walk": "horse-walk"}
FIT, TEST, TRAIN = (0, 300), (300, 600), (0, 240)
HAND_MASSES = [40.0, 150.0, 150.0, 40.0, 40.0, 40.0, 40.0]  # horse_trot_ground.toml's values
BODY = ("Head", "Withers", "Sacrum")


def per_marker(model, traj) -> tuple[float, list[float]]:
    """One-step RMS (mm) of ``model`` along ``traj``, overall and per marker."""
    from activebonds.identify.judge.predictions import one_step

    rec = np.asarray(traj.positions, np.float64)
    err2 = np.sum((one_step(model, rec, traj.dt) - rec) ** 2, axis=-1)
    ok = np.isfinite(err2)
    each = [float(np.sqrt(err2[ok[:, p], p].mean()) * 1000.0) for p in range(rec.shape[1])]
    return float(np.sqrt(err2[ok].mean()) * 1000.0), each


def zero_force(traj) -> tuple[float, list[float]]:
    from activebonds.identify.judge.baselines import zero_force_predictions

    rec = np.asarray(traj.positions, np.float64)
    err2 = np.sum((zero_force_predictions(rec, 1)[0] - rec) ** 2, axis=-1)
    ok = np.isfinite(err2)
    each = [float(np.sqrt(err2[ok[:, p], p].mean()) * 1000.0) for p in range(rec.shape[1])]
    return float(np.sqrt(err2[ok].mean()) * 1000.0), each


def scored(model, fitted, held, zero_each) -> dict:
    fit_rms, _ = per_marker(model, fitted)
    total, each = per_marker(model, held)
    ratios = [m / z for m, z in zip(each, zero_each, strict=True)]
    return {
        "bonds": sum(1 for b in model.spec.bond if not b.absent),
        "genes": model.layout.n_genes,
        "fit_rms_mm": fit_rms,
        "held_out_rms_mm": total,
        "per_marker_mm": each,
        "worst_ratio_to_zero_force": max(ratios),
        "every_marker_below_zero_force": all(r < 1 for r in ratios),
    }


def solved(spec, traj, frames, eliminate: bool):
    """The spec decided (``eliminate``: BIC) and solved on ``frames``: a Model."""
    from activebonds.identify.discover.structure import structure_of
    from activebonds.identify.settings import FitSettings
    from activebonds.model import build

    found = structure_of(build(spec), traj, FitSettings(frames=frames), 0, eliminate)
    return build(found.spec)


def with_masses(spec, masses):
    """The spec with these masses, every stiffness and damping (values and bounds) scaled by
    the ratio of the totals, so that the bounds stay as wide for the heavier body."""
    from activebonds.model.values import Param

    scale = float(sum(masses)) / sum(float(p.mass) for p in spec.particle)

    def scaled(v):
        if isinstance(v, Param):
            return v.model_copy(
                update={"value": v.value * scale, "min": v.min * scale, "max": v.max * scale}
            )
        return v * scale

    particles = [
        p.model_copy(update={"mass": m}) for p, m in zip(spec.particle, masses, strict=True)
    ]
    bonds = [
        b.model_copy(update={"stiffness": scaled(b.stiffness), "damping": scaled(b.damping)})
        for b in spec.bond
    ]
    update = {"particle": particles, "bond": bonds, "total_mass": float(sum(masses))}
    return spec.model_copy(update=update)


def issue_bounds(spec, traj):
    """The issue's 4.53 mm model: gravity, stiffness and damping from 0 (to 1e7 N/m and 1e5
    N s/m), rest lengths from 0 to 3 times the largest distance seen, anchors free 5 m about
    their mean positions."""
    from activebonds.model.values import Param, VectorParam

    x = np.asarray(traj.positions, np.float64)
    names = [p.name for p in spec.particle]
    out = []
    for b in spec.bond:
        ends = [x[:, names.index(n)] for n in b.particles]
        update = {
            "stiffness": Param(value=1000.0, min=0.0, max=1e7),
            "damping": Param(value=10.0, min=0.0, max=1e5),
        }
        if len(ends) == 2:
            d = np.linalg.norm(ends[1] - ends[0], axis=-1)
            update["rest_length"] = Param(
                value=float(np.median(d)), min=0.0, max=3 * float(d.max())
            )
        else:
            a = np.nanmean(ends[0], axis=0)
            update["anchor"] = VectorParam(
                value=[float(v) for v in a],
                min=[float(v - 5) for v in a],
                max=[float(v + 5) for v in a],
            )
        out.append(b.model_copy(update=update))
    return spec.model_copy(update={"bond": out, "gravity": [0.0, 0.0, -9.81]})


def fixed_at_means(spec, traj):
    """Rest lengths and anchors fixed at their means over ``traj`` (horse_structure.py's)."""
    x = np.asarray(traj.positions, np.float64)
    names = [p.name for p in spec.particle]
    out = []
    for b in spec.bond:
        ends = [x[:, names.index(n)] for n in b.particles]
        if len(ends) == 2:
            d = float(np.nanmean(np.linalg.norm(ends[1] - ends[0], axis=-1)))
            b = b.model_copy(update={"rest_length": d})
        else:
            b = b.model_copy(update={"anchor": [float(v) for v in np.nanmean(ends[0], axis=0)]})
        out.append(b)
    return spec.model_copy(update={"bond": out})


def run_gait(gait: str) -> dict:
    from activebonds.data import read_trajectory
    from activebonds.data.bundled import dataset
    from activebonds.identify.discover.scaffold import scaffold
    from activebonds.identify.discover.structure_choice import Variant, choose, decide, linear_spec
    from activebonds.model import build, loads_model

    traj = read_trajectory(dataset(GAITS[gait]).path)
    fitted, held = traj.window(*FIT), traj.window(*TEST)
    zero, zero_each = zero_force(held)
    out = {"gait": gait, "markers": list(traj.markers)}
    out["zero_force"] = {"held_out_rms_mm": zero, "per_marker_mm": zero_each}
    started = time.time()

    complete = loads_model(scaffold(traj, frames=FIT, gravity=False).text).spec
    old = loads_model(scaffold(traj, frames=FIT, gravity=False, complete=False).text).spec
    exact = {
        "the issue's (hand-written masses, gravity, wider bounds)": issue_bounds(
            with_masses(complete, HAND_MASSES), fitted
        ),
        "hand-written masses (500 kg)": with_masses(complete, HAND_MASSES),
        "scaffold masses (equal)": complete,
    }
    out["exact"] = {
        name: scored(solved(spec, traj, FIT, False), fitted, held, zero_each)
        for name, spec in exact.items()
    }
    no_anchor = linear_spec(complete, Variant(anchors="none"), fitted.positions, fitted.dt)
    ablations = {
        "neighbourhood candidates (before), every candidate": (old, False),
        "neighbourhood candidates (before), BIC-decided": (old, True),
        "complete graph, no anchor, every candidate": (no_anchor, False),
        "complete graph + anchors, rest lengths and anchors fixed at their means": (
            fixed_at_means(complete, fitted),
            False,
        ),
        "complete graph + anchors, BIC-decided": (complete, True),
    }
    out["ablations"] = {
        name: scored(solved(spec, traj, FIT, eliminate), fitted, held, zero_each)
        for name, (spec, eliminate) in ablations.items()
    }
    scaffolded = loads_model(scaffold(traj, frames=FIT).text)  # as auto writes it
    choice = choose(scaffolded, traj, FIT)
    out["choice"] = choice.record()
    out["variants"] = {}
    for s in choice.scored:
        model = build(decide(scaffolded, traj, FIT, s.variant).spec)
        out["variants"][s.variant.text()] = {
            "tail_rms_mm": s.tail_rms_mm,
            "tail_every_marker_better": s.every_marker_better,
            **scored(model, fitted, held, zero_each),
        }
    out["seconds"] = time.time() - started
    return out


def run_auto(gait: str, folder: Path, default: bool = False) -> dict:
    """``activebonds auto`` on the gait (held out: 300-599; ``default``: auto's own split,
    480-599), unless finished before; its held-out evaluation and the body markers' free-run
    count."""
    from activebonds.data import read_trajectory
    from activebonds.data.bundled import dataset
    from activebonds.identify.rundir import RunDir
    from activebonds.model import load_model
    from activebonds.report.evaluate import evaluate

    path = dataset(GAITS[gait]).path
    name = f"{gait}-default" if default else gait
    out_dir = folder / name
    split = [] if default else ["--held-out", "0.5"]
    command = ["activebonds", "auto", str(path), *split, "--out", str(out_dir)]
    state = out_dir / "auto.json"
    if not (state.is_file() and "report" in json.loads(state.read_text())["steps"]):
        folder.mkdir(parents=True, exist_ok=True)
        with open(folder / f"{name}.log", "w") as log:  # the command's own lines
            proc = subprocess.run(command, stdout=log, stderr=subprocess.STDOUT, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(command)} failed: see {folder / name}.log")
    record = json.loads(state.read_text())
    held = json.loads((out_dir / "evaluation.json").read_text())["held_out"]
    kept = out_dir / record["steps"]["fit"].get("run", "run")
    model = load_model(RunDir(kept).best_model_path)
    frames = tuple(held["frames"])
    body = evaluate(model, read_trajectory(path), frames=frames, body=BODY, horizon=1)
    one, ahead = held["comparisons"][0], held["comparisons"][1]
    return {
        "command": "activebonds auto $(activebonds datasets "
        f"{GAITS[gait]}) {' '.join(split)} --out {name}".replace("  ", " "),
        "held_out_frames": list(frames),
        "steps_seconds": {k: v["seconds"] for k, v in record["steps"].items()},
        "kept_run": kept.name,
        "structure": record["steps"]["structure"]["note"],
        "fit": record["steps"]["fit"]["note"],
        "held_out_rms_mm": one["model_mm"],
        "zero_force_rms_mm": one["zero_force_mm"],
        "per_marker_mm": one["model_per_marker_mm"],
        "zero_force_per_marker_mm": one["zero_force_per_marker_mm"],
        "ahead": {k: ahead[k] for k in ("horizon", "model_mm", "zero_force_mm")},
        "frames_within_50mm": held["model"]["median_frames_within"],
        "zero_force_frames_within_50mm": held["zero_force"]["median_frames_within"],
        "body_markers": list(BODY),
        "body_frames_within_50mm": body.body["model"].median_frames_within,
        "body_zero_force_frames_within_50mm": body.body["zero_force"].median_frames_within,
    }


def table(rows: dict, markers, zero: dict) -> str:
    head = "| model | bonds | fitted | held out | " + " | ".join(markers) + " | all below |"
    lines = [head, "|" + "---|" * (5 + len(markers))]
    for name, m in rows.items():
        cells = " | ".join(f"{v:.2f}" for v in m["per_marker_mm"])
        below = "yes" if m["every_marker_below_zero_force"] else "no"
        lines.append(
            f"| {name} | {m['bonds']} | {m['fit_rms_mm']:.3f} | {m['held_out_rms_mm']:.3f} | "
            f"{cells} | {below} |"
        )
    cells = " | ".join(f"{v:.2f}" for v in zero["per_marker_mm"])
    lines.append(f"| zero force | 0 | | {zero['held_out_rms_mm']:.3f} | {cells} | |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path)
    ap.add_argument("--auto", type=Path, help="Run activebonds auto into DIR/GAIT and read it.")
    ap.add_argument("--gait", choices=["trot", "walk", "both"], default="both")
    args = ap.parse_args(argv)
    gaits = list(GAITS) if args.gait == "both" else [args.gait]
    results = []
    for gait in gaits:
        r = run_gait(gait)
        if args.auto is not None:
            r["auto"] = run_auto(gait, args.auto)
            r["auto_default_split"] = run_auto(gait, args.auto, default=True)
        results.append(r)
        print(f"\n{gait}: fitted 0-299, held out 300-599 ({r['seconds']:.0f} s)")
        print(table({**r["exact"], **r["ablations"]}, r["markers"], r["zero_force"]))
        print(f"chosen on the tail: {r['choice']['chosen_text']}")
        print(table(r["variants"], r["markers"], r["zero_force"]))
        if "auto" in r:
            a = r["auto"]
            print(f"auto: {a['held_out_rms_mm']:.4g} mm, per marker {a['per_marker_mm']}")
    if args.json:
        record = {"command": "python scripts/heldout_horse.py " + " ".join(argv or sys.argv[1:])}
        args.json.write_text(json.dumps({**record, "results": results}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
