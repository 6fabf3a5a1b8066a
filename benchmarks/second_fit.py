"""A second fit of the same model and window in one process against the first: time to the
first generation and to the end, with the number of programs compiled (JAX's persistent-cache
misses) in each. ``fit`` keeps compiled programs (``activebonds.runtime.keep_compiled``), so
the second loads them instead of compiling.

    python benchmarks/second_fit.py [--out docs/results/second_fit.json]

Runs in a fresh child process with an empty cache folder, so the first fit compiles cold."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, time
from jax import monitoring
from activebonds import fit

misses = []
monitoring.register_event_listener(
    lambda name, **kw: misses.append(1) if name == "/jax/compilation_cache/cache_misses" else None
)

def one():
    began, first = time.perf_counter(), []
    def progress(*a, **k):
        if not first:
            first.append(time.perf_counter() - began)
    misses.clear()
    result = fit(
        "src/activebonds/examples/horse_limb.toml",
        "src/activebonds/datasets/horse_vhdc/Horse1_M1_trot1_kinematics.csv",
        markers=("Head", "Withers", "HFL"), frames=(0, FRAMES), bonds="neural",
        population=100, generations=20, seed=0, progress=progress,
    )
    return {"start_s": first[0], "total_s": time.perf_counter() - began,
            "compiled": len(misses), "rms_mm": result.rms_mm}

print(json.dumps([one(), one()]))
"""


def measure(frames: int) -> list[dict]:
    with tempfile.TemporaryDirectory(prefix="activebonds-second-fit-") as cache:
        env = dict(os.environ, ACTIVEBONDS_CACHE=cache)
        env.pop("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", None)
        out = subprocess.run(
            [sys.executable, "-c", CHILD.replace("FRAMES", str(frames))],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            check=True,
        )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    first, second = measure(args.frames)
    summary = {
        "case": f"horse limb, 3 markers, neural, frames 0:{args.frames}, population 100, "
        "20 generations",
        "first": first,
        "second": second,
        "start_ratio": first["start_s"] / second["start_s"],
        "total_ratio": first["total_s"] / second["total_s"],
        "command": "python benchmarks/second_fit.py",
    }
    print(json.dumps(summary, indent=2))
    if args.out:
        args.out.write_text(json.dumps(summary, indent=2) + "\n")


if __name__ == "__main__":
    main()
