"""The noisy MuJoCo recording of tests/test_auto_noise.py, written to a file.

    python scripts/mujoco_recording.py --out tendons.csv [--noise-mm 0.5] [--model start.toml]

Five free point masses (0.5-2.1 kg) joined by eight spring-damper tendons, simulated by MuJoCo
(RK4 at 1e-4 s), 5 s at 100 Hz, 0.5 mm Gaussian marker noise: the recording of
docs/howto/auto.md's "MuJoCo tendons" row (``activebonds auto tendons.csv --total-mass 5.824
--out tendons``). Prints the truth (masses; each tendon's stiffness, damping, rest length).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--noise-mm", type=float, default=0.5, help="marker noise (mm)")
    ap.add_argument(
        "--model",
        type=Path,
        help="also write the model family, every parameter "
        "free from a wrong start (mujoco_truth's model_toml('start'))",
    )
    args = ap.parse_args(argv)
    from activebonds.data.writers import write_trajectory
    from test_auto_noise import noisy_tendons

    truth, noisy = noisy_tendons(args.noise_mm / 1000.0)
    write_trajectory(noisy, args.out)
    if args.model is not None:
        args.model.write_text(truth.model_toml("start"))
    print(
        f"wrote {args.out}: {noisy.n_frames} frames at {noisy.rate:g} Hz, total mass "
        f"{sum(truth.masses):.4f} kg"
    )
    print("masses (kg):", ", ".join(f"{m:.4f}" for m in truth.masses))
    for b in truth.bonds:
        i, j = b.particles
        print(
            f"P{i}-P{j}: stiffness {b.stiffness:.4f} N/m, damping {b.damping:.4f} N s/m, "
            f"rest length {b.rest_length:.5f} m"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
