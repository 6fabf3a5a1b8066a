"""A body thrown onto a floor, simulated by MuJoCo: the recording of a new user's run.

    python scripts/mujoco_thrown.py --out thrown.csv [--noise-mm 0.5]

Five point masses (Nose 0.3, Tail 0.5, Left 0.4, Right 0.6, Top 0.8 kg: 2.6 kg) on slide
joints, joined by nine spring-damper tendons (800-3000 N/m, 0.5-3 N s/m), each a 2 cm sphere
on a floor with friction 0.08; thrown from 0.6 m (2.5, 0.4, 0.5 m/s, spinning): 39 frames in
flight, then it lands, folds, slides and stops. MuJoCo at 1 ms (implicitfast), recorded at
100 Hz for 4 s, written in mm (``# units: mm``). Prints the truth. Then, e.g.:
``activebonds auto thrown.csv --total-mass 2.6 --out thrown``, and

    python scripts/mujoco_thrown.py --compare thrown/run-ground

sets a fitted run's masses and springs beside the truth: each mass, each tendon's stiffness
and damping, the run's 95 % interval (``uncertainty.csv``; a parameter the run held has
none), its error and whether the interval holds the truth, then the uncertainty's warnings.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np

NAMES = ("Nose", "Tail", "Left", "Right", "Top")
MASS = {"Nose": 0.30, "Tail": 0.50, "Left": 0.40, "Right": 0.60, "Top": 0.80}
POS = {  # m, from the body's origin at the start
    "Nose": (0.15, 0.00, 0.00),
    "Tail": (-0.15, 0.00, 0.00),
    "Left": (0.00, 0.10, 0.00),
    "Right": (0.00, -0.10, 0.00),
    "Top": (0.00, 0.00, 0.14),
}
TENDONS = (  # (a, b, stiffness N/m, damping N s/m), rest lengths the start's distances
    ("Nose", "Left", 2000.0, 2.0),
    ("Nose", "Right", 1500.0, 1.5),
    ("Tail", "Left", 2500.0, 2.5),
    ("Tail", "Right", 1800.0, 1.0),
    ("Nose", "Top", 1200.0, 1.2),
    ("Tail", "Top", 3000.0, 3.0),
    ("Left", "Top", 2200.0, 2.0),
    ("Right", "Top", 1000.0, 0.8),
    ("Nose", "Tail", 800.0, 0.5),
)
RADIUS, FRICTION = 0.02, 0.08
ORIGIN = np.array([0.0, 0.0, 0.60])
VELOCITY, SPIN = np.array([2.5, 0.4, 0.5]), np.array([1.0, 2.0, 5.0])  # m/s, rad/s
RATE, SECONDS, SEED = 100, 4.0, 12345


def xml() -> str:
    friction = f"{FRICTION} 0.005 0.0001"
    bodies = "".join(
        f'<body name="{n}" pos="{" ".join(map(str, ORIGIN + POS[n]))}">'
        + "".join(
            f'<joint name="{n}_{a}" type="slide" axis="{ax}"/>'
            for a, ax in (("x", "1 0 0"), ("y", "0 1 0"), ("z", "0 0 1"))
        )
        + f'<geom type="sphere" size="{RADIUS}" mass="{MASS[n]}" friction="{friction}" '
        f'condim="3" solref="0.015 0.1"/><site name="s_{n}" size="0.005"/></body>'
        for n in NAMES
    )
    tendons = "".join(
        f'<spatial name="{a}-{b}" stiffness="{k}" damping="{c}" springlength="'
        f'{np.linalg.norm(np.subtract(POS[a], POS[b]))}"><site site="s_{a}"/>'
        f'<site site="s_{b}"/></spatial>'
        for a, b, k, c in TENDONS
    )
    return (
        '<mujoco model="thrown"><option timestep="0.001" gravity="0 0 -9.81" '
        'integrator="implicitfast"/><worldbody><geom name="floor" type="plane" '
        f'size="5 5 0.1" friction="{friction}"/>{bodies}</worldbody>'
        f"<tendon>{tendons}</tendon></mujoco>"
    )


def simulate() -> np.ndarray:
    """Marker positions [F, 5, 3] (m) at :data:`RATE`."""
    import mujoco

    m = mujoco.MjModel.from_xml_string(xml())
    d = mujoco.MjData(m)
    for n in NAMES:
        v = VELOCITY + np.cross(SPIN, POS[n])  # a rigid throw
        for i, a in enumerate("xyz"):
            d.qvel[m.jnt_dofadr[m.joint(f"{n}_{a}").id]] = v[i]
    steps = int(round(1.0 / (RATE * m.opt.timestep)))
    out = np.zeros((int(round(SECONDS * RATE)) + 1, len(NAMES), 3))
    for f in range(len(out)):
        mujoco.mj_forward(m, d)  # the sites at the current state (mj_step leaves them stale)
        out[f] = [d.site(f"s_{n}").xpos for n in NAMES]
        for _ in range(steps if f < len(out) - 1 else 0):
            mujoco.mj_step(m, d)
    return out


def _held(run: Path) -> tuple[dict[str, float], dict[tuple[str, str, str], float]]:
    """The run's best model: its masses (kg) by particle, and each spring's stiffness and
    damping by (a, b, parameter), fitted or held."""
    from activebonds.model import load_model

    model = load_model(run / "best_model.toml")
    names = [p.name for p in model.spec.particle]
    masses = dict(zip(names, map(float, model.params.mass), strict=True))
    springs = {}
    for b in model.spec.bond:
        if b.kind == "binary":
            for what in ("stiffness", "damping"):
                v = getattr(b, what)
                springs[(*b.particles, what)] = float(getattr(v, "value", v))
    return masses, springs


def compare(run: Path) -> list[str]:
    """A fitted run's masses and tendons beside the truth, in lines (see the module's
    docstring)."""
    with (run / "uncertainty.csv").open(encoding="utf-8") as f:
        rows = {r["label"]: r for r in csv.DictReader(f)}
    masses, springs = _held(run)
    out = ["particle mass: fitted [95 % interval] vs truth: error"]
    for name, truth in MASS.items():
        row = rows.get(f"particle {name} mass")
        span = f" [{float(row['ci95_low']):.4g}, {float(row['ci95_high']):.4g}]" if row else ""
        how = "" if row else " (not fitted in this run)"
        error = 100.0 * (masses[name] / truth - 1.0)
        out.append(f"  {name}: {masses[name]:.4g}{span} vs {truth}: {error:+.1f} %{how}")
    out.append("tendon, parameter: fitted [95 % interval] vs truth: error, interval holds it")
    for a, b, k, c in TENDONS:
        for what, truth in (("stiffness", k), ("damping", c)):
            row = rows.get(f"spring {a}-{b} {what}") or rows.get(f"spring {b}-{a} {what}")
            held = springs.get((a, b, what), springs.get((b, a, what)))
            if row is None and held is not None:
                error = 100.0 * (held / truth - 1.0)
                out.append(
                    f"  {a}-{b} {what}: {held:.4g} (held: not fitted in this run) vs {truth}: "
                    f"{error:+.1f} %, -"
                )
                continue
            if row is None:
                out.append(f"  {a}-{b} {what}: not in the fitted model (truth {truth})")
                continue
            value = float(row["value"])
            if row["determined"] == "yes":
                low, high = float(row["ci95_low"]), float(row["ci95_high"])
                span, holds = f"[{low:.4g}, {high:.4g}]", "yes" if low <= truth <= high else "no"
            else:
                span, holds = "[not determined]", "-"
            error = 100.0 * (value / truth - 1.0)
            out.append(f"  {a}-{b} {what}: {value:.4g} {span} vs {truth}: {error:+.1f} %, {holds}")
    record = json.loads((run / "uncertainty.json").read_text())
    out += [f"warning: {w}" for w in record.get("warnings", [])]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="the recording to write (CSV)")
    ap.add_argument("--noise-mm", type=float, default=0.0, help="marker noise (mm)")
    ap.add_argument("--compare", type=Path, help="a fitted run directory to set beside the truth")
    args = ap.parse_args(argv)
    if args.compare:
        print("\n".join(compare(args.compare)))
        return 0
    if args.out is None:
        ap.error("--out or --compare is required")
    x = simulate()
    x = x + np.random.default_rng(SEED).normal(0.0, args.noise_mm / 1000.0, x.shape)
    head = ["Frame#", "Time"] + [f"{n}{a}" for n in NAMES for a in "XYZ"]
    rows = [
        ",".join([str(f + 1), f"{f / RATE:.4f}", *(f"{v:.4f}" for v in 1000.0 * x[f].ravel())])
        for f in range(len(x))
    ]
    args.out.write_text(
        f"# units: mm\n# rate: {RATE}\n" + ",".join(head) + "\n" + "\n".join(rows) + "\n"
    )
    print(f"wrote {args.out}: {len(x)} frames at {RATE} Hz, noise {args.noise_mm} mm")
    print("masses (kg):", MASS, "total", sum(MASS.values()))
    for a, b, k, c in TENDONS:
        rest = np.linalg.norm(np.subtract(POS[a], POS[b]))
        print(f"  {a}-{b}: stiffness {k} N/m, damping {c} N s/m, rest length {rest:.4f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
