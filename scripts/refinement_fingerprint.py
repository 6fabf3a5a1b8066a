"""A fingerprint of the refinement and the uncertainty, to compare two checkouts to the bit
(usage: python scripts/refinement_fingerprint.py OUT_FOLDER; run it in each checkout, with
that checkout's src first on PYTHONPATH, and compare the two OUT_FOLDER/fingerprint.json).

The triangle of examples/triangle.toml, 80 frames at 100 Hz with 0.3 mm of noise (seed 0),
fitted twice (standard bonds, population 16, 20 generations, seed 1): a restart curriculum
(horizons 1, 5) and multiple shooting (horizon 10, 2 Verlet substeps). The fingerprint holds
the final genomes, every refinement stage's record but its wall time, uncertainty.csv and
uncertainty.json (its substeps check included)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from activebonds import fit
from activebonds.model import load_model
from activebonds.simulation import simulate

ROOT = Path(__file__).resolve().parents[1]
FITS = {
    "restart": {"cost": "restart", "horizon": (1, 5)},
    "shoot": {"cost": "shooting", "horizon": (10,), "substeps": 2, "integrator": "verlet"},
}


def fingerprint(out: Path) -> dict:
    model = ROOT / "examples" / "triangle.toml"
    rec = simulate(load_model(model), 80, 100.0)
    noise = np.random.default_rng(0).normal(0.0, 3e-4, rec.positions.shape)
    rec = rec.with_positions(rec.positions + noise)
    found = {}
    for name, options in FITS.items():
        run = out / name
        result = fit(
            model, rec, bonds="standard", population=16, generations=20, seed=1, out=run, **options
        )
        stages = [
            {k: v for k, v in s.record().items() if k != "seconds"} for s in result.refinement
        ]
        record = json.loads((run / "uncertainty.json").read_text())
        record.pop("seconds", None)
        found[name] = {
            "genome": [float(g) for g in result.genome],
            "stages": stages,
            "uncertainty_csv": (run / "uncertainty.csv").read_text(),
            "uncertainty": record,
        }
    return found


if __name__ == "__main__":
    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    (out / "fingerprint.json").write_text(json.dumps(fingerprint(out), indent=1, sort_keys=True))
    print(out / "fingerprint.json")
