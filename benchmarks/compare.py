"""Generations/s of this checkout against another one (e.g. the previous commit), pair by pair.

    git worktree add /tmp/base HEAD~1
    python benchmarks/compare.py /tmp/base [--rounds 3] [--only paper]

Each round runs ``benchmarks/run.py --quick --only SECTION --json`` of the other checkout and
then of this one, each in a fresh process importing its own ``src`` (PYTHONPATH), so the two
are measured alternately on the same machine under the same load. For every configuration the
ratio (this / other) of adjacent runs is taken, and the median over rounds reported; the
target of an architecture change is a ratio of at least 0.95 everywhere.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def run_once(tree: Path, section: str, out: Path) -> dict[tuple, float]:
    env = dict(os.environ, PYTHONPATH=str(tree / "src"))
    cmd = [sys.executable, str(tree / "benchmarks" / "run.py"), "--quick", "--only", section]
    subprocess.run([*cmd, "--json", str(out)], env=env, check=True, stdout=subprocess.DEVNULL)
    report = json.loads(out.read_text())
    rows = [r for r in report.get("configs", []) if r.get("section") == section]
    return {(r["config"], r["population"]): float(r["gens_per_s"]) for r in rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("other", type=Path, help="the other checkout (a git worktree)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--only", default="paper")
    ap.add_argument("--json", type=Path, help="write the ratios to this JSON file")
    args = ap.parse_args(argv)
    ratios: dict[tuple, list[float]] = {}
    rates: dict[tuple, list[tuple[float, float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            other = run_once(args.other.resolve(), args.only, Path(tmp) / f"other{r}.json")
            this = run_once(HERE, args.only, Path(tmp) / f"this{r}.json")
            for key in sorted(set(other) & set(this)):
                ratios.setdefault(key, []).append(this[key] / other[key])
                rates.setdefault(key, []).append((other[key], this[key]))
            print(f"round {r + 1}/{args.rounds} done", file=sys.stderr, flush=True)
    print(f"{'config':34s} {'pop':>5s} {'other gen/s':>12s} {'this gen/s':>11s} {'ratio':>6s}")
    out = []
    for key, rs in ratios.items():
        o = statistics.median(a for a, _ in rates[key])
        t = statistics.median(b for _, b in rates[key])
        med = statistics.median(rs)
        out.append({"config": key[0], "population": key[1], "ratio": med, "ratios": rs})
        print(f"{key[0]:34s} {key[1]:5d} {o:12.1f} {t:11.1f} {med:6.3f}")
    worst = min(r["ratio"] for r in out)
    print(f"lowest median ratio: {worst:.3f} ({'ok' if worst >= 0.95 else 'SLOWER'}: target 0.95)")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
