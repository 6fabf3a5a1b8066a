"""The README's recommended command for real data, end to end, on a recording it never saw.

    python benchmarks/recommended.py [--frames 300] [--noise-mm 0.5] [--json out.json]

The recording: MuJoCo's tendon tetrahedron (4 particles, 6 tendons, 18 genes; RK4 at 1e-4 s,
``tests/mujoco_truth.py``, seed 3) sampled at 100 Hz, ``--frames`` frames, with Gaussian
marker noise, written to a CSV file; the model: the same family with every parameter free
inside wide bounds (``model_toml("start")``). Each command runs as a new user would run it,
in its own process (compilation included, JAX's persistent cache off so no run profits from
an earlier one):

* ``recommended``: ``activebonds fit MODEL DATA --init lsq --cost shooting --horizon 10
  --substeps 20 --integrator verlet``;
* ``five``: the same with ``--substeps 5`` (Verlet's error at 5 substeps of 2 ms on these
  springs, omega h below 0.06, is far below the noise's);
* ``default``: ``activebonds fit MODEL DATA`` (``--cost auto``: multiple shooting here).

Per command: its wall-clock seconds, the refinement's stages (cost, steps, seconds, message)
and every parameter's relative error against MuJoCo's truth (max and median per kind).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT.parent / "tests"))

SHOOTING = ["--init", "lsq", "--cost", "shooting", "--horizon", "10", "--integrator", "verlet"]
COMMANDS = {
    "recommended": [*SHOOTING, "--substeps", "20"],
    "five": [*SHOOTING, "--substeps", "5"],
    "default": [],
}
KINDS = ("stiffness", "rest_length", "damping")


def recording(frames: int, noise_mm: float, folder: Path):
    import mujoco_truth
    from activebonds.data import Trajectory, write_trajectory

    truth = mujoco_truth.tendon_system(4, rate=100.0, seconds=(frames - 1) / 100.0, seed=3)
    clean = truth.trajectory()
    rng = np.random.default_rng(1003)
    noisy = clean.positions + rng.normal(0.0, noise_mm / 1000.0, clean.positions.shape)
    data = folder / "tendons.csv"
    write_trajectory(
        Trajectory(positions=noisy, markers=clean.markers, rate=clean.rate, mask=clean.mask), data
    )
    model = folder / "tendons.toml"
    model.write_text(truth.model_toml("start"))
    return truth, model, data


def errors(truth, model_path: Path, run: Path) -> dict:
    import mujoco_truth
    from activebonds.model import load_model

    model = load_model(model_path)
    stages = json.loads((run / "refine.json").read_text())["stages"]
    nat = model.layout.natural(np.asarray(stages[-1]["genome"]))
    by_name = {g.name: v for g, v in zip(model.layout.genes, nat, strict=True)}
    out = {k: [] for k in KINDS}
    for bond in truth.bonds:
        i, j = bond.particles
        name = mujoco_truth.bond_type(i, j, len(truth.markers))
        for kind in KINDS:
            out[kind].append(abs(by_name[f"type:{name}.{kind}"] / getattr(bond, kind) - 1.0))
    return {
        k: {"max_pct": 100 * max(v), "median_pct": 100 * float(np.median(v))}
        for k, v in out.items()
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--noise-mm", type=float, default=0.5)
    parser.add_argument("--commands", default="recommended,five,default")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    record = {"frames": args.frames, "noise_mm": args.noise_mm, "commands": {}}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        truth, model, data = recording(args.frames, args.noise_mm, folder)
        for name in args.commands.split(","):
            run = folder / name
            argv = ["activebonds", "fit", str(model), str(data), "--out", str(run)]
            argv += COMMANDS[name]
            env = {**os.environ, "ACTIVEBONDS_CACHE": "off"}
            started = time.perf_counter()
            out = subprocess.run(argv, capture_output=True, text=True, env=env)
            seconds = time.perf_counter() - started
            if out.returncode != 0:
                record["commands"][name] = {"failed": out.stderr.strip().splitlines()[-3:]}
                continue
            stages = json.loads((run / "refine.json").read_text())["stages"]
            row = {
                "command": " ".join(["activebonds", "fit", "MODEL", "DATA", *COMMANDS[name]]),
                "seconds": round(seconds, 1),
                "stages": [
                    {k: s[k] for k in ("cost", "horizon", "steps", "seconds", "message")}
                    for s in stages
                ],
                "errors": errors(truth, model, run),
            }
            record["commands"][name] = row
            print(name, json.dumps({k: v for k, v in row.items() if k != "stages"}), flush=True)
            if args.json:
                args.json.write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
