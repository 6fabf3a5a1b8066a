"""The package against a previous version of itself, measured in the same run, pair by pair.

    python benchmarks/versions.py [--base REV] [--new REV] [--quick] [--only CASES] [--json out.json]

"new" is the working tree's ``src/`` (copied once at the start, so that edits made while the
benchmark runs do not mix into it), or ``--new REV``; "old" is ``src/`` of ``--base REV``
(default 0d44234, the last commit before the ES speed work), extracted with ``git archive``.
Every measurement is a fresh child process (``versions_child.py``, same interpreter,
``PYTHONPATH`` = that tree's ``src``; the child checks where ``activebonds`` was imported from),
run alternately new, old, new, old, ...; each adjacent (new, old) pair gives a ratio, and the
table reports every pair's ratio and their median. Ratios are speed-ups: new/old for rates,
old/new for times, so > 1 means the new version is faster.

Cases (``--only``, comma-separated):

* full10, full60, full600 - the full horse (7 markers, 21 mechanical-neural bonds), frames 0:10,
  0:60, 0:600 (the whole recording), population 500: steady generations per minute, from the
  progress callbacks after the first one (the first chunk holds the compilation), over
  >= 20 s (--quick: 6 s); the best RMS at the last generation both sides reached;
* human41 - 41 markers of tests/data/human_opensim/subject01_walk1.trc, each bonded
  (mechanical-neural) to its 3 nearest markers by mean distance, frames 0:120, population 200:
  as above;
* paper - the paper's horse end to end (examples/horse_limb.toml, trot, Head/Withers/HFL,
  frames 0:10, neural, population 500, 50,000 generations; --quick 5,000): wall time of
  ``fit`` with compilation, and each side's final best RMS;
* mesh100 - a 10x10 mesh (100 particles, 342 standard bonds), 60 simulated frames,
  population 500, chunk 1: compile time, as the time to the first progress callback minus
  one steady chunk, and as JAX's compile events;
* fit10 - a 10-generation fit of the full horse, 600 frames, population 500, default chunk:
  wall time of ``fit``, split into compile (JAX's events) + 10 steady generations + the rest.

The persistent JAX compilation cache is off in every child (cold compiles on both sides).
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
CHILD = HERE / "versions_child.py"
TRC = REPO / "tests" / "data" / "human_opensim" / "subject01_walk1.trc"
DEFAULT_BASE = "0d44234"
HORSE_MARKERS = ["Head", "Withers", "HFL"]
CASES = ("full10", "full60", "full600", "human41", "paper", "mesh100", "fit10")
BIG = 100_000  # generations of a time-bounded fit (stopped from the progress callback)


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def git(*args: str) -> str:
    out = subprocess.run(["git", "-C", str(REPO), *args], capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"git {' '.join(args)}: {out.stderr.strip()}")
    return out.stdout.strip()


# ---------------------------------------------------------------------------------------------
# the two trees


def extract(rev: str, dest: Path) -> dict:
    """``src/`` of ``rev`` into ``dest/src`` (git archive | tar)."""
    full = git("rev-parse", "--verify", f"{rev}^{{commit}}")
    dest.mkdir(parents=True)
    archive = subprocess.Popen(
        ["git", "-C", str(REPO), "archive", full, "src"], stdout=subprocess.PIPE
    )
    subprocess.run(["tar", "-x", "-C", str(dest)], stdin=archive.stdout, check=True)
    if archive.wait() != 0:
        raise SystemExit(f"git archive {rev} src failed")
    return {
        "rev": rev,
        "commit": full,
        "short": git("rev-parse", "--short", full),
        "subject": git("log", "-1", "--format=%s", full)[:100],
        "src": str(dest / "src"),
    }


def snapshot_working_tree(dest: Path) -> dict:
    """The working tree's ``src/`` copied to ``dest/src``: HEAD's hash, + a hash of the
    uncommitted changes under src/ if any."""
    shutil.copytree(
        REPO / "src",
        dest / "src",
        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info"),
    )
    head = git("rev-parse", "--short", "HEAD")
    status = git("status", "--porcelain", "--", "src")
    changed = [line[3:] for line in status.splitlines()]
    label = head
    if changed:
        digest = hashlib.sha1()
        for path in sorted((dest / "src").rglob("*.py")):
            digest.update(str(path.relative_to(dest)).encode() + b"\0" + path.read_bytes())
        label = f"{head}+dirty:{digest.hexdigest()[:8]}"
    return {
        "rev": "working tree",
        "commit": git("rev-parse", "HEAD"),
        "short": label,
        "subject": "working tree"
        + (f" ({len(changed)} files changed under src/)" if changed else ""),
        "changed": changed,
        "src": str(dest / "src"),
    }


# ---------------------------------------------------------------------------------------------
# cases


def specs(quick: bool, min_s: float | None) -> dict[str, dict]:
    steady = min_s if min_s is not None else (6.0 if quick else 20.0)
    horse = {"population": 500, "bonds": "neural", "seed": 0, "generations": BIG}
    return {
        "full10": {**horse, "frames": 10, "chunk": 17, "min_s": steady},
        "full60": {**horse, "frames": 60, "chunk": 17, "min_s": steady},
        "full600": {**horse, "frames": 600, "chunk": 5, "min_s": steady},
        "human41": {
            "population": 200,
            "bonds": "neural",
            "seed": 0,
            "generations": BIG,
            "frames": 120,
            "chunk": 5,
            "k": 3,
            "trc": str(TRC),
            "min_s": steady,
        },
        "paper": {
            "markers": HORSE_MARKERS,
            "frames": 10,
            "bonds": "neural",
            "population": 500,
            "generations": 5_000 if quick else 50_000,
            "seed": 0,
        },
        "mesh100": {
            "population": 500,
            "bonds": "standard",
            "seed": 0,
            "frames": 60,
            "chunk": 1,
            "generations": 1 + (4 if quick else 8),
        },
        "fit10": {**horse, "frames": 600, "generations": 10, "steady_after": steady / 2},
    }


# per case: (metric key in the child's result, unit, higher is better?)
METRIC = {
    "full10": ("steady_gens_per_min", "gen/min", True),
    "full60": ("steady_gens_per_min", "gen/min", True),
    "full600": ("steady_gens_per_min", "gen/min", True),
    "human41": ("steady_gens_per_min", "gen/min", True),
    "paper": ("fit_wall_s", "fit s", False),
    "mesh100": ("first_chunk_minus_steady_s", "compile s", False),
    "fit10": ("fit_wall_s", "fit s", False),
}


def run_child(case: str, spec: dict, side: dict, workdir: Path, timeout: float) -> dict:
    workdir.mkdir(parents=True, exist_ok=True)
    full = {**spec, "case": case, "expect_root": side["src"], "workdir": str(workdir)}
    if side.get("precision"):  # --new-precision: a setting the old side may not know
        full["precision"] = side["precision"]
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_COMPILATION_CACHE")}
    env.update(
        PYTHONPATH=side["src"],
        JAX_ENABLE_COMPILATION_CACHE="false",
        ACTIVEBONDS_CACHE="off",
        PYTHONDONTWRITEBYTECODE="1",
    )
    t = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, "-P", str(CHILD), json.dumps(full)],
            capture_output=True,
            text=True,
            env=env,
            cwd=workdir,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:.0f} s"}
    wall = time.perf_counter() - t
    lines = proc.stdout.strip().splitlines()
    if proc.returncode != 0 or not lines:
        return {"error": (proc.stderr or proc.stdout)[-3000:], "returncode": proc.returncode}
    try:
        res = json.loads(lines[-1])
    except json.JSONDecodeError:
        return {"error": proc.stdout[-3000:] + proc.stderr[-2000:]}
    res["process_wall_s"] = wall
    return res


def speedup(case: str, new: dict, old: dict) -> float | None:
    key, _, higher = METRIC[case]
    a, b = new.get(key), old.get(key)
    if a is None or b is None or a <= 0 or b <= 0:
        return None
    return a / b if higher else b / a


def common_rms(new: dict, old: dict) -> dict | None:
    """Best RMS of both sides at the last generation both reported (same seed)."""
    if new.get("completed") and old.get("completed") and "rms_mm" in new and "rms_mm" in old:
        g = new["settings"]["generations"]
        a, b = new["rms_mm"], old["rms_mm"]
    else:
        na = {g: r for g, _, r in new.get("samples", [])}
        nb = {g: r for g, _, r in old.get("samples", [])}
        both = sorted(set(na) & set(nb))
        if not both:
            return None
        g = both[-1]
        a, b = na[g], nb[g]
    rel = abs(a - b) / max(abs(b), 1e-300) if math.isfinite(a) and math.isfinite(b) else None
    return {"generation": g, "new_rms_mm": a, "old_rms_mm": b, "rel_diff": rel}


def fit10_split(res: dict) -> dict:
    """wall = compile (JAX events) + 10 x steady generation + rest."""
    if "steady_s_per_gen" not in res:
        return {}
    gens = res["settings"]["generations"]
    run = gens * res["steady_s_per_gen"]
    return {
        "compile_s": res["compile_s"],
        "generations_s": run,
        "rest_s": res["fit_wall_s"] - res["compile_s"] - run,
    }


def measure(case: str, spec: dict, sides: dict, pairs: int, tmp: Path, timeout: float) -> dict:
    out: dict = {"case": case, "spec": spec, "pairs": []}
    for i in range(pairs):
        pair = {}
        for name in ("new", "old"):
            log(f"{case}: pair {i + 1}/{pairs}, {name} ({sides[name]['short']})")
            res = run_child(case, spec, sides[name], tmp / f"{case}-{i}-{name}", timeout)
            if "error" in res:
                log(f"  {name} FAILED: {res['error'].strip().splitlines()[-1:]}")
            else:
                key, unit, _ = METRIC[case]
                log(
                    f"  {unit} {_f(res.get(key))}; first callback {_f(res.get('first_callback_s'))} s; "
                    f"compile (JAX) {_f(res.get('compile_s'))} s; process {res['process_wall_s']:.1f} s"
                )
            pair[name] = res
        if "error" not in pair["new"] and "error" not in pair["old"]:
            pair["speedup"] = speedup(case, pair["new"], pair["old"])
            pair["rms"] = common_rms(pair["new"], pair["old"])
            if case == "fit10":
                pair["split"] = {s: fit10_split(pair[s]) for s in ("new", "old")}
            log(f"  speed-up new/old {_f(pair['speedup'], 3)}")
        out["pairs"].append(pair)
        if "error" in pair["new"] and "error" in pair["old"]:
            log(f"{case}: both sides failed; skipping its other pairs")
            break
    ratios = [p["speedup"] for p in out["pairs"] if p.get("speedup")]
    out["ratios"] = ratios
    out["median_speedup"] = statistics.median(ratios) if ratios else None
    for name in ("new", "old"):
        ok = [p[name] for p in out["pairs"] if "error" not in p[name]]
        key = METRIC[case][0]
        vals = [r[key] for r in ok if r.get(key) is not None]
        out[f"{name}_median"] = statistics.median(vals) if vals else None
        out[f"{name}_errors"] = [p[name]["error"] for p in out["pairs"] if "error" in p[name]]
    return out


# ---------------------------------------------------------------------------------------------
# report


def _f(x, digits=2) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if abs(x) >= 1000:
        return f"{x:,.0f}"
    if abs(x) >= 100:
        return f"{x:.1f}"
    return f"{x:.{digits}f}"


def _med(pairs, side, key):
    vals = [p[side][key] for p in pairs if key in p.get(side, {}) and p[side][key] is not None]
    return statistics.median(vals) if vals else None


def print_report(report: dict) -> None:
    from rich.console import Console
    from rich.table import Table

    console = Console(width=150)
    new, old = report["sides"]["new"], report["sides"]["old"]
    env = report["environment"]
    console.print(
        f"[bold]activebonds: new {new['short']} ({new['subject']}) vs old {old['short']} "
        f"({old['subject']})[/bold]\n{env['date']}  mode {'quick' if report['quick'] else 'full'}"
        f"  {report['pairs']} pairs per case  load average {env['loadavg_start'][0]:.1f} -> "
        f"{env['loadavg_end'][0]:.1f}  total {report['total_s']:.0f} s",
        markup=True,
        highlight=False,
    )
    for case, res in report["cases"].items():
        key, unit, higher = METRIC[case]
        pairs = res["pairs"]
        extra = _extra_columns(case)
        t = Table(
            title=f"{case}: {unit} ({'higher' if higher else 'lower'} is better); speed-up = "
            f"{'new/old' if higher else 'old/new'}",
            title_justify="left",
        )
        t.add_column("pair")
        t.add_column(f"new {unit}", justify="right")
        t.add_column(f"old {unit}", justify="right")
        t.add_column("speed-up", justify="right")
        for title, _ in extra:
            t.add_column(title, justify="right")
        for i, p in enumerate(pairs):
            t.add_row(
                str(i + 1),
                _val(p["new"], key),
                _val(p["old"], key),
                _f(p.get("speedup"), 3),
                *(fn(p) for _, fn in extra),
            )
        t.add_row(
            "median",
            _f(res["new_median"]),
            _f(res["old_median"]),
            _f(res["median_speedup"], 3) + "x" if res["median_speedup"] else "-",
            *("" for _ in extra),
            style="bold",
        )
        console.print(t)
        console.print(
            "  per-pair speed-ups: " + " ".join(_f(r, 3) for r in res["ratios"]), highlight=False
        )
        for name in ("new", "old"):
            for err in res[f"{name}_errors"][:1]:
                console.print(f"  [red]{name} failed[/red]: {err.strip()[-600:]}", markup=True)
        if case == "fit10":
            for i, p in enumerate(pairs):
                for name in ("new", "old"):
                    x = p.get("split", {}).get(name)
                    if x:
                        console.print(
                            f"  pair {i + 1} {name}: a 10-generation fit takes "
                            f"{p[name]['fit_wall_s']:.1f} s; compile {x['compile_s']:.1f} s + "
                            f"10 gens {x['generations_s']:.1f} s + {x['rest_s']:.1f} s (the rest)",
                            highlight=False,
                        )


def _val(res: dict, key: str) -> str:
    return "FAILED" if "error" in res else _f(res.get(key))


def _nv(p, key, digits=2):
    return f"{_f(p['new'].get(key), digits)} / {_f(p['old'].get(key), digits)}"


def _rms(p):
    r = p.get("rms")
    if not r:
        return "-"
    same = "=" if r["rel_diff"] == 0 else f"rel {r['rel_diff']:.1e}"
    return f"g{r['generation']}: {r['new_rms_mm']:.3f} / {r['old_rms_mm']:.3f} ({same})"


def _extra_columns(case: str):
    first = ("1st callback s new/old", lambda p: _nv(p, "first_callback_s", 1))
    jaxc = ("compile (JAX) s new/old", lambda p: _nv(p, "compile_s", 1))
    chunk = ("chunk new/old", lambda p: f"{_chunk(p['new'])} / {_chunk(p['old'])}")
    rms = ("best RMS mm new/old", _rms)
    if case == "mesh100":
        return [jaxc, first, ("chunk s new/old", lambda p: _nv(p, "median_chunk_s", 3))]
    if case == "paper":
        return [
            first,
            jaxc,
            ("steady gen/s new/old", lambda p: _nv(p, "steady_gens_per_s", 0)),
            rms,
        ]
    if case == "fit10":
        return [
            jaxc,
            ("s/gen new/old", lambda p: _nv(p, "steady_s_per_gen", 3)),
            chunk,
            rms,
        ]
    later = (
        "compiles after 1st s new/old",
        lambda p: _nv(p, "compile_after_first_callback_s", 1),
    )
    return [first, jaxc, later, chunk, rms]


def _chunk(res: dict) -> str:
    c = res.get("chunks") or []
    return ",".join(str(x) for x in c) if c else "-"


# ---------------------------------------------------------------------------------------------


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default=DEFAULT_BASE, help=f"old revision (default {DEFAULT_BASE})")
    ap.add_argument("--new", help="new revision (default: the working tree's src/)")
    ap.add_argument("--quick", action="store_true", help="shorter measurements, 2 pairs")
    ap.add_argument("--only", help=f"comma-separated cases of {','.join(CASES)}")
    ap.add_argument("--pairs", type=int, help="pairs per case (default 3; --quick 2)")
    ap.add_argument("--min-seconds", type=float, help="steady measurement per child (20; 6)")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per child")
    ap.add_argument("--json", type=Path, help="write every number to this JSON file")
    ap.add_argument("--keep", action="store_true", help="keep the temporary trees")
    ap.add_argument(
        "--new-precision",
        help="the new side's --precision (e.g. mixed); the old side keeps its default float64",
    )
    args = ap.parse_args(argv)
    only = args.only.split(",") if args.only else list(CASES)
    unknown = set(only) - set(CASES)
    if unknown:
        ap.error(f"unknown cases: {', '.join(sorted(unknown))}")
    pairs = args.pairs or (2 if args.quick else 3)

    started = time.perf_counter()
    tmp = Path(tempfile.mkdtemp(prefix="activebonds-versions-"))
    try:
        sides = {
            "new": extract(args.new, tmp / "new")
            if args.new
            else snapshot_working_tree(tmp / "new"),
            "old": extract(args.base, tmp / "old"),
        }
        if args.new_precision:
            sides["new"]["precision"] = args.new_precision
        for name, side in sides.items():
            log(f"{name}: {side['short']} {side['subject']}  (PYTHONPATH={side['src']})")
        report = {
            "quick": args.quick,
            "pairs": pairs,
            "sides": sides,
            "environment": {
                "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
                "command": " ".join([Path(sys.executable).name, *sys.argv]),
                "python": sys.version.split()[0],
                "cores": os.cpu_count(),
                "loadavg_start": os.getloadavg(),
            },
            "cases": {},
        }
        all_specs = specs(args.quick, args.min_seconds)
        for case in only:
            report["cases"][case] = measure(
                case, all_specs[case], sides, pairs, tmp / "runs", args.timeout
            )
        report["environment"]["loadavg_end"] = os.getloadavg()
        report["total_s"] = time.perf_counter() - started
    finally:
        if args.keep:
            log(f"kept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    print_report(report)
    if args.json:
        args.json.write_text(json.dumps(report, indent=1) + "\n")
        log(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
