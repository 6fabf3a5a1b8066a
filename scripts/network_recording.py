"""The simulated 8-particle network of tests/test_scaffold_recovery.py as a recording.

    python scripts/network_recording.py --out network.npz

8 particles of 0.5 kg on a perturbed 0.5 m cube, 21 springs, gravity, a frictionless ground
contact each; simulated at 1000 Hz, kept at 100 Hz (600 frames), 0.5 mm Gaussian marker
noise: the recording of docs/howto/auto.md's "simulated 8-particle network" row
(``activebonds auto network.npz --out network``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    from activebonds.data.trajectory import Trajectory
    from activebonds.data.writers import write_trajectory
    from activebonds.model import loads_model
    from activebonds.simulation import simulate
    from test_scaffold_recovery import FINE, FRAMES, NOISE, RATE, _truth

    text, _, rng = _truth()
    fine = simulate(loads_model(text), FRAMES * FINE, RATE * FINE)
    x = np.asarray(fine.positions)[::FINE]
    x = x + rng.normal(0.0, NOISE, x.shape)
    names = tuple(f"P{i}" for i in range(8))
    write_trajectory(Trajectory(x, np.ones(x.shape[:2], bool), names, RATE), args.out)
    print(f"wrote {args.out}: {x.shape[0]} frames at {RATE:g} Hz, {len(names)} markers")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
