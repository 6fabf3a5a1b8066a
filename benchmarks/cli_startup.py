"""Seconds the command line takes to answer without computing: help, version, bad options.

    python benchmarks/cli_startup.py [--runs 5]

Each case runs ``python -m activebonds.cli ARGS`` in a fresh process (the ``activebonds``
script does the same: import ``activebonds.cli.main``, call ``main()``) and is timed from
spawn to exit; ``python -c pass`` in the same run is the interpreter's own start-up, the floor.
The cases run round-robin, ``--runs`` times; each reports its median wall time and the median
CPU time (user + system) of its process, which a loaded machine does not inflate, with the
load average before the run. Target: every case's median wall time under 1 s. Prints JSON.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time

CASES = {
    "--help": ["--help"],
    "-h": ["-h"],
    "fit --help": ["fit", "--help"],
    "--version": ["--version"],
    "fit --bogus": ["fit", "--bogus"],
    "fit (missing arguments)": ["fit"],
    "info (missing arguments)": ["info"],
}


def seconds(argv: list[str]) -> tuple[float, float, int]:
    """(wall seconds, CPU seconds of the child, exit code) of one run."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, check=False)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, proc.returncode


def summary(runs: list[tuple[float, float, int]]) -> dict:
    walls, cpus, codes = zip(*runs, strict=True)
    return {
        "median_s": round(statistics.median(walls), 3),
        "min_s": round(min(walls), 3),
        "median_cpu_s": round(statistics.median(cpus), 3),
        "exit_code": codes[-1],
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=5)
    args = ap.parse_args(argv)
    load_before = os.getloadavg()
    cli = [sys.executable, "-m", "activebonds.cli"]
    argvs = {"python -c pass": [sys.executable, "-c", "pass"]}
    argvs.update({name: [*cli, *extra] for name, extra in CASES.items()})
    runs = {name: [] for name in argvs}
    for _ in range(args.runs):  # round-robin: a change of the machine's load hits every case
        for name, argv in argvs.items():
            runs[name].append(seconds(argv))
    load = [round(x, 2) for x in load_before]
    report = {
        "runs": args.runs,
        "load_average": load,
        "baseline": summary(runs.pop("python -c pass")),
    }
    report["cases"] = {name: summary(r) for name, r in runs.items()}
    report["all_under_1s"] = all(c["median_s"] < 1.0 for c in report["cases"].values())
    print(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
