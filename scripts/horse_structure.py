"""The horse: a model pruned from a complete candidate graph against the hand-written one.

    python scripts/horse_structure.py [--json docs/results/horse_structure.json]

For each gait of the bundled VHDC horse (Horse1_M1 trot1 and walk1, all 7 markers), on the
fit frames 0-299 and the held-out frames 300-599:

* ``hand-written``: examples/horse_trot_ground.toml's bonds that the exact least squares
  solves (its 11 binary bonds: neck, back, trunk, legs with diagonals; its 3 body anchors),
  with gravity and its masses fixed at the file's values (500 kg in all); the contacts are
  left out (they are not linear in their parameters);
* ``candidates``: the same particles, masses and gravity with every pair of markers joined by
  an optional binary spring-damper (21) and every marker tied by an optional unary
  spring-damper to a fixed anchor (7), each bond its own type, stiffness and damping free
  (from 0), rest lengths and anchors fixed at their means over the fit frames (free ones
  enter the least squares as bounded products, whose constrained solve takes ~10 s for this
  model: too slow for the hundreds of solves of an elimination path);
* ``hand-written`` is also given parametrised as the candidates (same bonds, rest lengths
  and anchors fixed at their means, stiffness and damping free from 0), so that the
  comparison with the pruned model is one of structure only;
* ``pruned``: the candidates after structure identification (backward elimination under the
  BIC on the exact one-step least squares, activebonds.identify.discover.structure).

Each is fitted by exact least squares on the fit frames and judged by its one-step RMS error
on the held-out frames (all markers and per marker), beside the zero-force predictor.
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.append(str(ROOT / "scripts"))
DATA = ROOT / "src" / "activebonds" / "datasets" / "horse_vhdc"
MODEL = ROOT / "src" / "activebonds" / "examples" / "horse_trot_ground.toml"
GAITS = {"trot": "Horse1_M1_trot1_kinematics.csv", "walk": "Horse1_M1_walk1_kinematics.csv"}
FIT, TEST = (0, 300), (300, 600)


def hand_written(fit=None):
    """The file's linear bonds, masses fixed; with ``fit``, parametrised as the candidates
    (rest lengths and anchors fixed at their means over the fit frames)."""
    from activebonds.model import build, load_model
    from activebonds.model.schema import Param

    spec = load_model(MODEL).spec
    particles = [p.model_copy(update={"mass": float(p.mass.value)}) for p in spec.particle]
    names = [p.name for p in spec.particle]
    kept = []
    for b in spec.bond:
        if b.kind not in ("binary", "unary"):
            continue
        if fit is not None:
            ends = [fit.positions[:, names.index(n)] for n in b.particles]
            if b.kind == "binary":
                d = float(np.nanmean(np.linalg.norm(ends[1] - ends[0], axis=-1)))
                b = b.model_copy(update={"rest_length": round(d, 4)})
            else:
                a = [round(float(v), 4) for v in np.nanmean(ends[0], axis=0)]
                b = b.model_copy(update={"anchor": a})
            free = Param(value=1000.0, min=0.0, max=1e6), Param(value=10.0, min=0.0, max=1e4)
            b = b.model_copy(update={"stiffness": free[0], "damping": free[1]})
        kept.append(b)
    update = {"particle": particles, "bond": kept, "total_mass": None, "name": "hand-written"}
    return build(spec.model_copy(update=update))


def candidate_text(fit) -> str:
    """Every pair joined and every marker anchored, all optional, values from the data."""
    spec = hand_written().spec
    x = fit.positions
    lines = ['name = "candidates"', "dimension = 3", "gravity = [0.0, 0.0, -9.81]"]
    for p in spec.particle:
        lines += ["", "[[particle]]", f'name = "{p.name}"', f"mass = {p.mass}"]
    names = [p.name for p in spec.particle]
    for i, j in itertools.combinations(range(len(names)), 2):
        d = float(np.nanmean(np.linalg.norm(x[:, j] - x[:, i], axis=-1)))
        lines += [
            "",
            "[[bond]]",
            'kind = "binary"',
            f'type = "{names[i]}-{names[j]}"',
            f'particles = ["{names[i]}", "{names[j]}"]',
            "optional = true",
            "stiffness = { value = 1000.0, min = 0.0, max = 1000000.0 }",
            f"rest_length = {d:.4f}",
            "damping = { value = 10.0, min = 0.0, max = 10000.0 }",
        ]
    for i, n in enumerate(names):
        a = np.nanmean(x[:, i], axis=0)
        lines += [
            "",
            "[[bond]]",
            'kind = "unary"',
            f'type = "anchor-{n}"',
            f'particles = ["{n}"]',
            "optional = true",
            "stiffness = { value = 1000.0, min = 0.0, max = 1000000.0 }",
            "damping = { value = 10.0, min = 0.0, max = 10000.0 }",
            "anchor = [{}]".format(", ".join(f"{v:.4f}" for v in a)),
        ]
    return "\n".join(lines) + "\n"


def exact_fit(model, windows):
    from activebonds.identify.solvers.lsq import least_squares

    return model.with_genome(least_squares(model, windows).genome)


def run_gait(gait: str) -> dict:
    from horse_ground import per_marker_rms, zero_force_per_marker

    from activebonds import read_trajectory
    from activebonds.identify.costs.windows import make_windows
    from activebonds.identify.discover.structure import identify_structure
    from activebonds.model import dumps_model, loads_model

    traj = read_trajectory(DATA / GAITS[gait])
    fit, held = traj.window(*FIT), traj.window(*TEST)
    windows = make_windows(fit.positions, fit.mask, fit.dt, 1)
    started = time.time()
    candidates = loads_model(candidate_text(fit), "candidates")
    found = identify_structure(candidates, windows)
    seconds = time.time() - started
    models = {
        "hand-written (file's parametrisation)": exact_fit(hand_written(), windows),
        "hand-written (as the candidates)": exact_fit(hand_written(fit), windows),
        "candidates (all present)": exact_fit(candidates, windows),
        "pruned": loads_model(dumps_model(found.spec), "pruned"),
    }
    out = {"gait": gait, "markers": list(traj.markers), "models": {}, "seconds": seconds}
    for name, model in models.items():
        fitted, _ = per_marker_rms(model, fit)
        total, each = per_marker_rms(model, held)
        n_bonds = sum(1 for b in model.spec.bond if not b.absent)
        out["models"][name] = {
            "bonds": n_bonds,
            "genes": model.layout.n_genes,
            "fit_rms_mm": fitted,
            "held_out_rms_mm": total,
            "per_marker_mm": each.tolist(),
        }
    zf, zf_each = zero_force_per_marker(held)
    out["zero_force"] = {"held_out_rms_mm": zf, "per_marker_mm": zf_each.tolist()}
    out["decisions"] = [
        {"bond": d.label, "present": d.present, "delta_bic": d.delta_bic} for d in found.decisions
    ]
    return out


def table(r: dict) -> str:
    head = "| model | bonds | fit (mm) | held out (mm) | " + " | ".join(r["markers"]) + " |"
    lines = [head, "|" + "---|" * (4 + len(r["markers"]))]
    for name, m in r["models"].items():
        cells = " | ".join(f"{v:.2f}" for v in m["per_marker_mm"])
        lines.append(
            f"| {name} | {m['bonds']} | {m['fit_rms_mm']:.3f} | {m['held_out_rms_mm']:.3f} | "
            f"{cells} |"
        )
    z = r["zero_force"]
    cells = " | ".join(f"{v:.2f}" for v in z["per_marker_mm"])
    lines.append(f"| zero force | 0 | | {z['held_out_rms_mm']:.3f} | {cells} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    results = [run_gait(g) for g in GAITS]
    for r in results:
        print(f"\n{r['gait']}: fit frames 0-299, held out 300-599 ({r['seconds']:.0f} s)")
        print(table(r))
        kept = [d["bond"] for d in r["decisions"] if d["present"]]
        print(f"kept {len(kept)} of {len(r['decisions'])}: {', '.join(kept)}")
    if args.json:
        record = {"command": "python scripts/horse_structure.py " + " ".join(argv or sys.argv[1:])}
        args.json.write_text(json.dumps({**record, "results": results}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
