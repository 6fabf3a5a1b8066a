"""Recovery of a synthetic hopper with gravity, ground contact and friction (issue 11).

    python scripts/ground_recovery.py [--population 200] [--generations 4000] [--seeds 0,1]
                                      [--noise-mm 0,1] [--smooth 0] [--json out.json]

The truth (``TRUTH`` below): a body particle (4 kg) on two feet (1 kg each) in 3D, joined by
viscoelastic bonds (two "leg" bonds sharing one type, one "foot" bond between the feet), each
foot in contact with the ground plane z = 0 (stiffness 2e4 N/m, damping 30 N s/m, friction
0.6), gravity 9.81 m/s^2 down. Dropped from 0.25 m with a forward velocity of 1.2 m/s and a
sideways spin, it lands, slides (friction acts), bounces and settles: 2 s at 200 Hz (400
frames), simulated with semi-implicit Euler, one step per frame.

The fit starts from the same file with every parameter free inside wide bounds (the values
in the file are not the truth), the masses free as ratios of the known total (6 kg), and the
gravity magnitude free (5 .. 15 m/s^2); one-step cost, the paper's ES. Reported: the relative
error of every identified parameter, without noise and with Gaussian marker noise of the given
standard deviation (mm, per axis); ``--smooth N`` fits with the restart states smoothed
(``fit --smooth``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

TRUTH = {
    "mass": {"body": 4.0, "foot_l": 1.0, "foot_r": 1.0},
    "gravity": 9.81,
    "leg": {"stiffness": 1500.0, "rest_length": 0.35, "damping": 4.0},
    "foot": {"stiffness": 800.0, "rest_length": 0.3, "damping": 2.0},
    "ground": {"stiffness": 20000.0, "damping": 30.0, "friction": 0.6, "height": 0.0},
}

MODEL = """
name = "hopper"
dimension = 3
gravity = {{ value = {gravity}, min = 5.0, max = 15.0, direction = [0.0, 0.0, -1.0] }}
total_mass = 6.0

[[particle]]
name = "body"
mass = {{ value = {m_body}, min = 0.5, max = 5.0 }}
position = [0.0, 0.0, 0.55]
velocity = [1.2, 0.0, 0.0]

[[particle]]
name = "foot_l"
mass = {{ value = {m_l}, min = 0.5, max = 5.0 }}
position = [0.05, 0.15, 0.25]
velocity = [1.2, 0.3, 0.0]

[[particle]]
name = "foot_r"
mass = {{ value = {m_r}, min = 0.5, max = 5.0 }}
position = [-0.05, -0.15, 0.25]
velocity = [1.2, -0.3, 0.0]

[[bond]]
kind = "binary"
type = "leg"
particles = ["body", "foot_l"]
stiffness = {{ value = {leg_k}, min = 10.0, max = 100000.0 }}
rest_length = {{ value = {leg_l}, min = 0.2, max = 0.5 }}
damping = {{ value = {leg_c}, min = 0.01, max = 100.0 }}

[[bond]]
kind = "binary"
type = "leg"
particles = ["body", "foot_r"]
stiffness = {{ value = {leg_k}, min = 10.0, max = 100000.0 }}
rest_length = {{ value = {leg_l}, min = 0.2, max = 0.5 }}
damping = {{ value = {leg_c}, min = 0.01, max = 100.0 }}

[[bond]]
kind = "binary"
type = "foot"
particles = ["foot_l", "foot_r"]
stiffness = {{ value = {foot_k}, min = 10.0, max = 100000.0 }}
rest_length = {{ value = {foot_l}, min = 0.2, max = 0.5 }}
damping = {{ value = {foot_c}, min = 0.01, max = 100.0 }}

[[bond]]
kind = "contact"
type = "ground"
particles = ["foot_l"]
normal = [0.0, 0.0, 1.0]
height = {{ value = {g_h}, min = -0.05, max = 0.05 }}
stiffness = {{ value = {g_k}, min = 1000.0, max = 1000000.0 }}
damping = {{ value = {g_c}, min = 0.1, max = 1000.0 }}
friction = {{ value = {g_mu}, min = 0.0, max = 2.0 }}

[[bond]]
kind = "contact"
type = "ground"
particles = ["foot_r"]
normal = [0.0, 0.0, 1.0]
height = {{ value = {g_h}, min = -0.05, max = 0.05 }}
stiffness = {{ value = {g_k}, min = 1000.0, max = 1000000.0 }}
damping = {{ value = {g_c}, min = 0.1, max = 1000.0 }}
friction = {{ value = {g_mu}, min = 0.0, max = 2.0 }}
"""


def model_text(values: dict) -> str:
    m, g = values["mass"], values["ground"]
    return MODEL.format(
        gravity=values["gravity"], m_body=m["body"], m_l=m["foot_l"], m_r=m["foot_r"],
        leg_k=values["leg"]["stiffness"], leg_l=values["leg"]["rest_length"],
        leg_c=values["leg"]["damping"], foot_k=values["foot"]["stiffness"],
        foot_l=values["foot"]["rest_length"], foot_c=values["foot"]["damping"],
        g_h=g["height"], g_k=g["stiffness"], g_c=g["damping"], g_mu=g["friction"],
    )  # fmt: skip


def identified(model) -> dict:
    """The parameters of a fitted model, named as in TRUTH."""
    spec = model.spec
    value = lambda p: p.value if hasattr(p, "value") else float(p)  # noqa: E731
    out = {"mass": {p.name: value(p.mass) for p in spec.particle}}
    out["gravity"] = value(spec.gravity) if not isinstance(spec.gravity, list) else 9.81
    for b in spec.bond:
        keys = ("stiffness", "rest_length", "damping")
        if b.kind == "contact":
            keys = ("stiffness", "damping", "friction", "height")
        out[b.type] = {k: value(getattr(b, k)) for k in keys}
    return out


def errors(found: dict, truth: dict) -> dict[str, float]:
    """Relative errors (absolute, in m, for the plane height whose truth is 0)."""
    out = {}
    for group, values in truth.items():
        if isinstance(values, dict):
            for k, v in values.items():
                f = found[group][k]
                out[f"{group}.{k}"] = (f - v) if v == 0 else (f - v) / v
        else:
            out[group] = (found[group] - values) / values
    return out


def main(argv=None) -> int:
    from activebonds import fit, simulate
    from activebonds.data import Trajectory
    from activebonds.model import loads_model
    from activebonds.runtime import fast_cpu_flags

    fast_cpu_flags()
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--population", type=int, default=200)
    ap.add_argument("--generations", type=int, default=4000)
    ap.add_argument("--seeds", default="0,1")
    ap.add_argument("--noise-mm", default="0,1")
    ap.add_argument("--smooth", type=int, default=0, help="fit --smooth window (0: off)")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)

    truth_model = loads_model(model_text(TRUTH), "truth")
    clean = simulate(truth_model, 400, 200.0)
    z = clean.positions[..., 2]
    contact = (z[:, 1:] < 0).mean()
    print(f"truth: feet below the plane in {100 * contact:.0f} % of frames", file=sys.stderr)
    start = {  # the fit's file values: not the truth
        "mass": {"body": 2.0, "foot_l": 2.0, "foot_r": 2.0},
        "gravity": 8.0,
        "leg": {"stiffness": 300.0, "rest_length": 0.3, "damping": 1.0},
        "foot": {"stiffness": 300.0, "rest_length": 0.25, "damping": 1.0},
        "ground": {"stiffness": 5000.0, "damping": 10.0, "friction": 1.0, "height": 0.01},
    }
    to_fit = loads_model(model_text(start), "start")
    rows = []
    for noise in [float(s) for s in args.noise_mm.split(",")]:
        for seed in [int(s) for s in args.seeds.split(",")]:
            rng = np.random.default_rng(100 + seed)
            x = clean.positions + rng.normal(0.0, noise / 1000.0, clean.positions.shape)
            data = Trajectory(positions=x, mask=clean.mask, markers=clean.markers, rate=200.0)
            res = fit(
                to_fit, data, population=args.population, generations=args.generations,
                seed=seed, smooth=args.smooth, refine="none",
            )  # fmt: skip
            err = errors(identified(res.model), TRUTH)
            rows.append({"noise_mm": noise, "seed": seed, "rms_mm": res.rms_mm, "errors": err})
            worst = max(abs(v) for k, v in err.items() if not k.endswith("height"))
            print(f"noise {noise} mm seed {seed}: fit {res.rms_mm:.3g} mm, "
                  f"worst relative error {100 * worst:.2f} %", file=sys.stderr)  # fmt: skip
    names = list(rows[0]["errors"])
    print(
        "| parameter | "
        + " | ".join(f"noise {r['noise_mm']:g} mm, seed {r['seed']}" for r in rows)
        + " |"
    )
    print("|---|" + "---|" * len(rows))
    for n in names:
        cells = []
        for r in rows:
            e = r["errors"][n]
            cells.append(f"{1000 * e:+.2f} mm" if n.endswith("height") else f"{100 * e:+.3f} %")
        print(f"| {n} | " + " | ".join(cells) + " |")
    print("| fit RMS (mm) | " + " | ".join(f"{r['rms_mm']:.3g}" for r in rows) + " |")
    if args.json:
        args.json.write_text(json.dumps({"truth": TRUTH, "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
