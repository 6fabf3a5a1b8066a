"""float64 against ``--precision mixed`` (the ES's one-step cost in float32): speed and quality.

    python benchmarks/precision.py [--seeds 5] [--quick] [--json out.json]

For each problem and seed, the same fit (``activebonds.identify.fit``) runs once in float64 and
once in mixed precision, one after the other (pairs, so that load drifts hit both alike). Speed:
the median over chunks (after the first, which compiles) of generations per second, as a
ratio per pair. Quality: the final best RMS, which ``fit`` always recomputes in
float64, so the two columns are the same measure; mixed precision is worth it only where the
ratio is > 1 and the RMS is not worse across seeds.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import problems as P  # noqa: E402
from activebonds.identify import fit  # noqa: E402
from activebonds.model import loads_model  # noqa: E402


def _cases(quick: bool):
    horse = P.horse_trajectory()
    paper = P.EXAMPLES / "horse_limb.toml"
    full = loads_model(P.full_horse_toml(horse), "<horse_full>")
    return {
        "paper horse (pop 500, 10 frames)": (
            paper,
            dict(markers=P.HORSE_MARKERS, frames=(0, 10), bonds="neural", population=500),
            1000 if quick else 5000,
        ),
        "full horse (pop 500, 600 frames)": (
            full,
            dict(frames=(0, 600), bonds="neural", population=500),
            60 if quick else 300,
        ),
    }


def _one(model, options, generations, seed, precision):
    marks = []

    def progress(gen, total, rms):
        marks.append((time.perf_counter(), gen))

    result = fit(
        model,
        P.horse_trajectory(),
        generations=generations,
        seed=seed,
        precision=precision,
        progress=progress,
        refine="none",  # the ES's speed and quality: no refinement after it
        **options,
    )
    # steady speed: the median over chunks after the first (a chunk that compiled a new
    # length is an outlier the median ignores)
    rates = [
        (g1 - g0) / (t1 - t0)
        for (t0, g0), (t1, g1) in zip(marks, marks[1:], strict=False)
        if t1 > t0
    ]
    rate = statistics.median(rates) if rates else float("nan")
    return {"gen_per_s": rate, "rms_mm": float(result.rms_mm)}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    out = {}
    for name, (model, options, generations) in _cases(args.quick).items():
        rows = []
        for seed in range(args.seeds):
            f64 = _one(model, options, generations, seed, "float64")
            mixed = _one(model, options, generations, seed, "mixed")
            rows.append({"seed": seed, "float64": f64, "mixed": mixed})
            print(
                f"{name}  seed {seed}: float64 {f64['gen_per_s']:.1f} gen/s, "
                f"{f64['rms_mm']:.4f} mm | mixed {mixed['gen_per_s']:.1f} gen/s, "
                f"{mixed['rms_mm']:.4f} mm | speed x{mixed['gen_per_s'] / f64['gen_per_s']:.2f}",
                flush=True,
            )
        ratios = [r["mixed"]["gen_per_s"] / r["float64"]["gen_per_s"] for r in rows]
        better = sum(r["mixed"]["rms_mm"] <= r["float64"]["rms_mm"] for r in rows)
        summary = {
            "generations": generations,
            "median_speedup": statistics.median(ratios),
            "median_rms_float64": statistics.median(r["float64"]["rms_mm"] for r in rows),
            "median_rms_mixed": statistics.median(r["mixed"]["rms_mm"] for r in rows),
            "mixed_not_worse": f"{better}/{len(rows)} seeds",
        }
        print(f"{name}: {json.dumps(summary)}", flush=True)
        out[name] = {"rows": rows, "summary": summary}
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
