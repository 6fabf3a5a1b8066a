"""Coverage of the uncertainty report's 95 % intervals on noisy synthetic data.

    python scripts/uncertainty_coverage.py [--model examples/triangle.toml] [--datasets 50]
        [--frames 200] [--rate 100] [--noise-mm 0.5] [--json docs/results/uncertainty_coverage.json]

Each dataset: the model simulated from its file values (the truth), independent Gaussian
noise on every coordinate, a fit from the data alone (exact one-step least squares, then
multiple shooting over the whole window with Levenberg-Marquardt), and the Gauss-Newton
intervals. Prints the pooled coverage (target 90-98 %), the coverage per parameter, and the
mean standard error beside the spread of the estimates across datasets.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default=str(ROOT / "src/activebonds/examples/triangle.toml"))
    ap.add_argument("--datasets", type=int, default=50)
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--noise-mm", type=float, default=0.5)
    ap.add_argument("--json", default=None)
    a = ap.parse_args()

    from activebonds.experiments.coverage import coverage, trial
    from activebonds.model import load_model

    model = load_model(a.model)
    trials = []
    started = time.time()
    for seed in range(a.datasets):
        t = trial(model, a.frames, a.rate, a.noise_mm / 1000.0, seed)
        trials.append(t)
        print(
            f"dataset {seed}: {sum(t.inside)}/{len(t.inside)} inside, rms {t.rms_mm:.4f} mm, "
            f"{t.message} ({time.time() - started:.0f} s)",
            flush=True,
        )
    names = trials[0].names
    inside = np.array([t.inside for t in trials])
    values = np.array([t.values for t in trials])
    ses = np.array([[np.nan if s is None else s for s in t.std_errors] for t in trials])
    per = {
        n: {
            "truth": trials[0].truth[i],
            "coverage": float(inside[:, i].mean()),
            "mean_std_error": float(np.nanmean(ses[:, i])),
            "median_std_error": float(np.nanmedian(ses[:, i])),
            "median_abs_error": float(np.median(np.abs(values[:, i] - trials[0].truth[i]))),
            "spread_of_estimates": float(np.std(values[:, i], ddof=1)),
            "mean_estimate": float(values[:, i].mean()),
        }
        for i, n in enumerate(names)
    }
    total = coverage(trials)
    # A fit that ends far above the noise (a local minimum, a rejected stage) is counted
    # above; the share of fits that reached the noise level, and their coverage, beside it.
    noise_rms = np.sqrt(3.0) * a.noise_mm  # the RMS 3D distance of the noise alone
    reached = [t for t in trials if t.rms_mm < 1.2 * noise_rms]
    print(f"pooled coverage of the 95 % intervals: {total:.4f} ({inside.sum()}/{inside.size})")
    print(
        f"fits that reached the noise level (RMS < 1.2 x {noise_rms:.3f} mm): {len(reached)} of "
        f"{len(trials)}, their coverage {coverage(reached):.4f}"
    )
    for n, r in per.items():
        print(
            f"  {n:28s} coverage {r['coverage']:.2f}  median s.e. {r['median_std_error']:.4g}  "
            f"median |error| {r['median_abs_error']:.4g}"
        )
    if a.json:
        record = {
            "command": "python " + " ".join(["scripts/uncertainty_coverage.py", *sys.argv[1:]]),
            "model": Path(a.model).name,
            "datasets": a.datasets,
            "frames": a.frames,
            "rate_hz": a.rate,
            "noise_mm": a.noise_mm,
            "pooled_coverage": total,
            "intervals": int(inside.size),
            "per_parameter": per,
            "fits_at_noise_level": len(reached),
            "coverage_of_those": coverage(reached),
            "trials": [
                {"seed": t.seed, "rms_mm": t.rms_mm, "message": t.message, "inside": t.inside}
                for t in trials
            ],
            "seconds": round(time.time() - started, 1),
        }
        Path(a.json).write_text(json.dumps(record, indent=2) + "\n")


if __name__ == "__main__":
    main()
