"""Record the golden reference fits that tests/test_golden.py matches (to 1e-12 relative).

Three tiny float64 fits, each a pure function of (model, data, settings, seed):

* ``triangle_standard``: examples/triangle.toml, plain viscoelastic bonds, horizon 1, on its
  own 30-frame simulated trajectory (tests/golden/triangle_30.csv);
* ``horse_neural``: examples/horse_limb.toml, mechanical-neural bonds, the first 40 frames of
  the bundled VHDC horse trot (markers Head, Withers, HFL);
* ``chain2d``: examples/chain2d.toml, 2-D, a shared binary bond type, ternary flexion
  springs, a unary anchor spring and gravity, on its own 40-frame simulated trajectory
  (tests/golden/chain2d_40.csv).

For each, tests/golden/<case>.json stores the settings, the best cost every 10 generations,
the final best cost and genome and the number of failed evaluations.

Run it when a change of results is intended (ES, operators, random numbers, physics, cost):

    python scripts/record_golden.py          # re-record tests/golden/
    python scripts/record_golden.py --check  # compare only; exit 1 on a difference
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden"
EXAMPLES = ROOT / "src" / "activebonds" / "examples"
HORSE_TROT = (
    ROOT / "src" / "activebonds" / "datasets" / "horse_vhdc" / "Horse1_M1_trot1_kinematics.csv"
)
EVERY = 10
RTOL = 1e-12
COMMAND = "python scripts/record_golden.py"

CASES: dict[str, dict] = {
    "triangle_standard": {
        "model": "triangle.toml",
        "data": "golden:triangle_30.csv",
        "settings": {"bonds": "standard", "horizon": 1, "population": 30, "generations": 200,
                     "seed": 11},
    },
    "horse_neural": {
        "model": "horse_limb.toml",
        "data": "horse",
        "settings": {"bonds": "neural", "frames": [0, 40], "population": 24, "generations": 150,
                     "seed": 5},
    },
    "chain2d": {
        "model": "chain2d.toml",
        "data": "golden:chain2d_40.csv",
        "settings": {"population": 30, "generations": 200, "seed": 7},
    },
}  # fmt: skip

# The simulated recordings: (model, frames, rate).
RECORDINGS = {
    "triangle_30.csv": ("triangle.toml", 30, 60.0),
    "chain2d_40.csv": ("chain2d.toml", 40, 60.0),
}


def data_path(case: dict) -> Path:
    if case["data"] == "horse":
        return HORSE_TROT
    return GOLDEN / case["data"].removeprefix("golden:")


def record_data() -> None:
    """(Re)write the simulated recordings the golden fits use."""
    from activebonds.data import write_trajectory
    from activebonds.model import load_model
    from activebonds.simulation import simulate

    for name, (model, frames, rate) in RECORDINGS.items():
        write_trajectory(simulate(load_model(EXAMPLES / model), frames, rate), GOLDEN / name)


def compute(name: str) -> dict:
    """Run golden fit ``name`` (float64, in this process) and summarise it."""
    import jax
    import numpy as np

    from activebonds.identify import FitSettings, fit

    jax.config.update("jax_enable_x64", True)
    case = CASES[name]
    # the ES alone (the refinement, FitSettings' default, would polish its best)
    settings = FitSettings(**{"refine": "none", **case["settings"]}, precision="float64")
    result = fit(EXAMPLES / case["model"], data_path(case), settings)
    best = np.asarray(result.history["best_cost"], dtype=np.float64)
    return {
        "case": name,
        "model": f"examples/{case['model']}",
        "data": case["data"],
        "settings": case["settings"],
        "status": result.status,
        "every": EVERY,
        "best_cost": [float(x) for x in best[EVERY - 1 :: EVERY]],
        "final_cost": float(result.cost),
        "final_genome": [float(x) for x in result.genome],
        "genes": [g.name for g in result.identification.model.layout.genes],
        "failed_evaluations": int(np.asarray(result.history["failed"]).sum()),
        "generations": int(len(best)),
    }


def _close(a: float, b: float) -> bool:
    return a == b or abs(a - b) <= RTOL * max(abs(a), abs(b))


def compare(stored: dict, fresh: dict) -> list[str]:
    """Differences between a stored and a fresh summary (empty: they match)."""
    problems = []
    for key in ("status", "settings", "every", "genes", "failed_evaluations", "generations"):
        if stored.get(key) != fresh.get(key):
            problems.append(f"{key}: stored {stored.get(key)!r}, now {fresh.get(key)!r}")
    for g, (a, b) in enumerate(zip(stored["best_cost"], fresh["best_cost"], strict=False)):
        if not _close(a, b):
            gen = (g + 1) * stored["every"]
            problems.append(f"best cost at generation {gen}: stored {a!r}, now {b!r}")
            break
    if len(stored["best_cost"]) != len(fresh["best_cost"]):
        problems.append("number of recorded generations differs")
    if not _close(stored["final_cost"], fresh["final_cost"]):
        problems.append(f"final cost: stored {stored['final_cost']!r}, now {fresh['final_cost']!r}")
    genome = list(zip(stored["final_genome"], fresh["final_genome"], strict=False))
    bad = [i for i, (a, b) in enumerate(genome) if not _close(a, b)]
    if bad or len(stored["final_genome"]) != len(fresh["final_genome"]):
        problems.append(f"final genome differs (genes {bad[:5]})")
    return problems


def golden_file(name: str) -> Path:
    return GOLDEN / f"{name}.json"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--check", action="store_true", help="compare only, write nothing")
    p.add_argument("cases", nargs="*", default=list(CASES), help="cases (default: all)")
    a = p.parse_args(argv)
    GOLDEN.mkdir(parents=True, exist_ok=True)
    if not a.check:
        record_data()
    status = 0
    for name in a.cases:
        fresh = compute(name)
        if a.check:
            problems = compare(json.loads(golden_file(name).read_text()), fresh)
            print(f"{name}: {'matches' if not problems else '; '.join(problems)}")
            status |= bool(problems)
        else:
            golden_file(name).write_text(json.dumps(fresh, indent=1) + "\n")
            print(f"{name}: recorded (final cost {fresh['final_cost']!r})")
    return status


if __name__ == "__main__":
    sys.exit(main())
