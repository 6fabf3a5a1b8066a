"""``activebonds auto`` over a dataset: N trials on two Ray workers against the same N one
after another, and against one trial alone.

    python benchmarks/dataset.py [--frames 300] [--json out.json]

The trials: sections of the bundled horse recordings (``--frames`` frames each: the trot's
and the walk's first and second sections), written as CSV files. Three commands, each in a
new process with an empty compilation cache (cold, as a new user runs them):

* ``one``: ``auto`` of the first trial alone;
* ``sequential``: ``auto`` of all N trials ``--sequential`` (one process, one after another);
* ``ray``: ``auto`` of all N trials ``--workers 2`` (a local Ray cluster of two workers).

Reported: each command's wall seconds, ``ray / sequential`` (the target: at most 0.6 of N
trials' time one after another) and ``ray / (N x one)``; and whether the three give the same
numbers for the trials they share (summary.csv).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "src/activebonds/datasets/horse_vhdc"
KEYS = ("trial", "status", "family", "one_step_mm", "zero_force_one_step_mm", "ahead_mm")


def trials(folder: Path, frames: int) -> list[Path]:
    from activebonds.data import Trajectory, read_trajectory, write_trajectory

    out = []
    for gait in ("trot", "walk"):
        t = read_trajectory(DATA / f"Horse1_M1_{gait}1_kinematics.csv")
        for i in range(2):
            rows = slice(i * frames, (i + 1) * frames)
            path = folder / f"{gait}{i + 1}.csv"
            write_trajectory(Trajectory(t.positions[rows], t.mask[rows], t.markers, t.rate), path)
            out.append(path)
    return out


def command(paths: list[Path], out: Path, cache: Path, *extra: str) -> float:
    env = dict(os.environ, ACTIVEBONDS_CACHE=str(cache), RAY_USAGE_STATS_ENABLED="0")
    cmd = [sys.executable, "-m", "activebonds.cli", "auto", *map(str, paths), "--out", str(out)]
    start = time.perf_counter()
    proc = subprocess.run([*cmd, *extra], capture_output=True, text=True, env=env, check=False)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(proc.stderr[-2000:])
    return wall


def rows(out: Path) -> dict[str, tuple]:
    summary = out / "summary.csv"
    if not summary.is_file():  # one recording: auto's own folder
        return {}
    with open(summary, newline="") as f:
        return {r["trial"]: tuple(r[k] for k in KEYS) for r in csv.DictReader(f)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        paths = trials(work, args.frames)
        n = len(paths)
        one = command(paths[:1], work / "one", work / "c1")
        seq = command(paths, work / "seq", work / "c2", "--sequential")
        par = command(paths, work / "ray", work / "c3", "--workers", "2")
        same = rows(work / "seq") == rows(work / "ray")
    result = {
        "trials": n,
        "frames": args.frames,
        "load_average": os.getloadavg(),
        "one_s": round(one, 1),
        "sequential_s": round(seq, 1),
        "ray_two_workers_s": round(par, 1),
        "ray_over_sequential": round(par / seq, 3),
        "ray_over_n_times_one": round(par / (n * one), 3),
        "same_numbers": same,
    }
    print(json.dumps(result, indent=1))
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
