"""The structure search at lab scale (issue 45): backward elimination under the BIC on a
scaffold of OpenSim's walk (``activebonds datasets human-walk``, 41 markers, 60 Hz, its first
120 frames) with ``--neighbours`` nearest neighbours per marker (6: 163 candidate bonds), by
branch and bound (``structure.best_removal``: every removal's BIC bounded from one
factorisation, one or two bounded solves a step) against every removal solved, each with one
BLAS thread, and the branch and bound with the BLAS library's own threads. Ratios in one run
(the machine is shared and noisy); the choices compared.

    python benchmarks/structure.py                  # bound, one thread vs default threads
    python benchmarks/structure.py --every          # and every removal solved (minutes)
    python benchmarks/structure.py --json out.json
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from threadpoolctl import threadpool_limits

from activebonds.data.bundled import dataset
from activebonds.data.readers import read_trajectory
from activebonds.identify.costs.windows import make_windows
from activebonds.identify.discover import structure as S
from activebonds.identify.discover.scaffold import scaffold
from activebonds.identify.problem import select_data
from activebonds.identify.settings import FitSettings
from activebonds.model import loads_model


def case(neighbours: int, frames: int):
    rec = read_trajectory(dataset("human-walk").path)
    found = scaffold(rec, frames=(0, frames), gravity=False, neighbours=neighbours, name="walk")
    model = loads_model(found.text, "walk.toml")
    data = select_data(model, rec, FitSettings(frames=(0, frames)))
    return model, make_windows(data.positions, data.mask, data.dt, 1)


def timed(run):
    start = time.perf_counter()
    result = run()
    return result, time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--neighbours", type=int, default=6)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--every", action="store_true", help="also solve every removal")
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    model, windows = case(args.neighbours, args.frames)
    n = len(S.candidates(model.spec))
    print(f"walk, {args.frames} frames, {n} candidate bonds")
    rows = {}
    bound, rows["bound, 1 thread"] = timed(lambda: S.identify_structure(model, windows))
    with threadpool_limits(limits=None):  # the library's own threads inside
        original = S.threadpool_limits
        S.threadpool_limits = lambda **_: threadpool_limits(limits=None)
        try:
            threads, rows["bound, BLAS threads"] = timed(
                lambda: S.identify_structure(model, windows)
            )
        finally:
            S.threadpool_limits = original
    same = {"bound, BLAS threads": threads.removed == bound.removed}
    if args.every:
        keep = S._Subsets.lower_bounds
        S._Subsets.lower_bounds = lambda self, present, scorer: None
        try:
            every, rows["every removal, 1 thread"] = timed(
                lambda: S.identify_structure(model, windows)
            )
        finally:
            S._Subsets.lower_bounds = keep
        same["every removal, 1 thread"] = every.removed == bound.removed
    base = rows["bound, 1 thread"]
    print(f"{'search':26s} {'s':>8s} {'x bound':>8s}  same choices")
    for name, seconds in rows.items():
        print(f"{name:26s} {seconds:8.2f} {seconds / base:8.2f}  {same.get(name, True)}")
    kept = sum(d.present for d in bound.decisions)
    print(
        f"kept {kept} of {n}; one-step RMS {bound.rms_mm:.4g} mm "
        f"(every candidate {bound.full_rms_mm:.4g}, zero force {bound.zero_force_rms_mm:.4g})"
    )
    if args.json:
        record = {
            "candidates": n,
            "seconds": rows,
            "same_choices": same,
            "kept": kept,
            "rms_mm": bound.rms_mm,
            "zero_force_rms_mm": bound.zero_force_rms_mm,
            "removed": [int(i) for i in np.asarray(bound.removed)],
        }
        with open(args.json, "w") as f:
            json.dump(record, f, indent=2)


if __name__ == "__main__":
    main()
