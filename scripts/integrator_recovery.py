"""The audit's recovery: fit the 4-particle, 6-bond tetrahedron (tests/models/tetra.toml) to
150 frames at 50 Hz simulated with the same integrator and substeps (default population
300 x 4,000 generations, as the audit), and print how far the 18 identified parameters are from the truth.

usage: python scripts/integrator_recovery.py [euler|verlet] [SUBSTEPS] [SEED] [POP] [GENS]
(run it with PYTHONPATH=OTHER/src to measure another checkout of the package)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

try:
    from activebonds import fit, load_model, simulate
except ImportError:  # a checkout before the top-level API (0.1.0)
    from activebonds.simulate import simulate

    from activebonds.identify import fit
    from activebonds.model import load_model

TETRA = Path(__file__).resolve().parents[1] / "tests" / "models" / "tetra.toml"


def main() -> None:
    method = sys.argv[1] if len(sys.argv) > 1 else "euler"
    substeps = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    seed = int(sys.argv[3]) if len(sys.argv) > 3 else 0
    population = int(sys.argv[4]) if len(sys.argv) > 4 else 300
    generations = int(sys.argv[5]) if len(sys.argv) > 5 else 4000
    truth = load_model(TETRA)
    data = simulate(truth, 150, 50.0, substeps=substeps, integrator=method)
    start = time.time()
    result = fit(
        truth, data, population=population, generations=generations, seed=seed, substeps=substeps,
        integrator=method, refine="none",
    )  # fmt: skip
    names = [g.name for g in truth.layout.genes]
    rel = (
        result.model.layout.natural(result.genome) / truth.layout.natural(truth.layout.initial())
        - 1.0
    )
    k = [i for i, n in enumerate(names) if n.endswith("stiffness")]
    c = [i for i, n in enumerate(names) if n.endswith("damping")]
    print(
        f"{method}, {substeps} substep(s), seed {seed}, {population} x {generations}: "
        f"{time.time() - start:.0f} s, "
        f"RMS {result.rms_mm:.3g} mm, max |relative error| {np.abs(rel).max():.2e}, "
        f"mean stiffness error {rel[k].mean():+.2e}, mean damping error {rel[c].mean():+.2e}"
    )


if __name__ == "__main__":
    main()
