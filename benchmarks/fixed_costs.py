"""What a user waits for around the numerics: each command's wall time, split into JAX's
compilation and the rest, cold (a new process, an empty compilation cache) or warm.

    python benchmarks/fixed_costs.py [--old-python /path/to/efdebe3/.venv/bin/python]
                                     [--pairs 2] [--only paper,recommended,run7,auto] [--json out.json]

Every command runs in its own process through ``fixed_costs_child.py`` (the command line's
``main()`` in that process, JAX's compile events recorded: tracing, lowering, XLA's backend
compile, and the persistent cache's hits and misses). "cold": ``ACTIVEBONDS_CACHE`` an empty
folder made for that command; "warm": the folder of the fit the command follows.

Cases:

* ``paper``: the paper's horse through the command line, defaults: ``fit
  examples/horse_limb.toml HORSE --markers Head,Withers,HFL --frames 0:10 --bonds neural
  --population 500 --generations 15000``, cold; with ``--old-python`` (an environment where an
  earlier version is installed, e.g. commit efdebe3: ``git worktree add /tmp/old efdebe3 &&
  python -m venv /tmp/old/.venv && /tmp/old/.venv/bin/pip install /tmp/old``) the same command
  of that version beside it, new and old alternating ``--pairs`` times; the ratio old / new per
  pair (> 1: the new is faster).
* ``recommended``: the README's recommended command for real data (``fit MODEL DATA --init lsq
  --cost shooting --horizon 10 --substeps 20 --integrator verlet``) on MuJoCo's tendon
  tetrahedron, 300 frames at 100 Hz with 0.5 mm noise, 18 parameters
  (``benchmarks/recommended.py``'s recording), cold.
* ``run7``: a 7-marker, 600-frame run (``scaffold`` of the bundled trot, ``fit --generations
  200``), then, warm, ``report`` of it, ``evaluate`` of its model on the recording, and ``fill``
  of one 60-frame gap (marker HFL blanked over frames 300-359 of the recording).
* ``auto``: ``auto`` of the bundled trot, cold: the cache misses between one candidate's line
  and the next (each candidate's fit).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
CHILD = HERE / "fixed_costs_child.py"
HORSE = ROOT / "src/activebonds/datasets/horse_vhdc/Horse1_M1_trot1_kinematics.csv"
LIMB = ROOT / "src/activebonds/examples/horse_limb.toml"
PAPER = ["--markers", "Head,Withers,HFL", "--frames", "0:10", "--bonds", "neural"]
PAPER += ["--population", "500", "--generations", "15000"]
RECOMMENDED = ["--init", "lsq", "--cost", "shooting", "--horizon", "10", "--substeps", "20"]
RECOMMENDED += ["--integrator", "verlet"]


def command(argv: list[str], cache: Path, python: str = sys.executable, log=None) -> dict:
    """One command in a child process: wall seconds (spawn to exit), the child's own record
    (compile seconds by kind, cache hits and misses) and its output's lines, timestamped."""
    out = Path(tempfile.mkstemp(suffix=".json")[1])
    env = dict(os.environ, ACTIVEBONDS_CACHE=str(cache), PYTHONUNBUFFERED="1")
    start = time.perf_counter()
    proc = subprocess.Popen(
        [python, "-P", str(CHILD), str(out), *map(str, argv)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        env=env,
        text=True,
    )
    lines = [(time.perf_counter() - start, line.rstrip()) for line in proc.stdout]
    code = proc.wait()
    wall = time.perf_counter() - start
    record = json.loads(out.read_text()) if out.stat().st_size else {"events": []}
    out.unlink()
    compile_s = {}
    for e in record["events"]:
        if e["event"] in ("jaxpr_trace", "jaxpr_to_mlir_module", "backend_compile"):
            compile_s[e["event"]] = compile_s.get(e["event"], 0.0) + e["seconds"]
    if log is not None:
        log.write(f"$ activebonds {' '.join(map(str, argv))}\n")
        log.writelines(f"{t:7.2f} {text}\n" for t, text in lines)
    return {
        "argv": list(map(str, argv)),
        "code": code if record.get("code") is None else record["code"],
        "wall": wall,
        "compile": {k: round(v, 3) for k, v in compile_s.items()},
        "compile_total": round(sum(compile_s.values()), 3),
        "cache": record.get("cache", {}),
        "events": record["events"],
        "lines": lines,
    }


def summary(name: str, got: dict) -> dict:
    return {
        "case": name,
        "wall_s": round(got["wall"], 2),
        "compile_cpu_s": got["compile_total"],
        "programs_compiled": got["cache"].get("cache_misses", 0),
        "exit": got["code"],
    }


def paper(work: Path, pairs: int, old_python: str | None, log) -> list[dict]:
    rows = []
    for i in range(pairs):
        for side, python, limb in (("new", sys.executable, LIMB), ("old", old_python, None)):
            if python is None:
                continue
            if limb is None:  # the old version's own copy of the example
                found = subprocess.run(
                    [python, "-c", "import activebonds, pathlib; print(pathlib.Path("
                     "activebonds.__file__).parent / 'examples' / 'horse_limb.toml')"],
                    capture_output=True, text=True, check=True,
                )  # fmt: skip
                limb = found.stdout.strip()
            out = work / f"paper-{side}-{i}"
            argv = ["fit", limb, HORSE, *PAPER, "--out", out]
            got = command(argv, work / f"cache-paper-{side}-{i}", python, log)
            rows.append({**summary(f"paper {side} (pair {i + 1})", got), "side": side})
    return rows


def recommended(work: Path, log) -> list[dict]:
    sys.path.insert(0, str(ROOT / "tests"))
    sys.path.insert(0, str(HERE))
    from recommended import recording  # noqa: PLC0415 - benchmark's sibling

    _, model, data = recording(300, 0.5, work)
    got = command(
        ["fit", model, data, *RECOMMENDED, "--out", work / "rec"], work / "cache-rec", log=log
    )
    return [summary("recommended, tetrahedron 300 frames, cold", got)]


def run7(work: Path, log) -> list[dict]:
    from activebonds.data import Trajectory, read_trajectory, write_trajectory  # noqa: PLC0415

    cache = work / "cache-run7"
    model, run = work / "horse7.toml", work / "run7"
    rows = [summary("scaffold", command(["scaffold", HORSE, "--out", model], cache, log=log))]
    rows.append(summary("fit, 7 markers, 600 frames, 200 generations",
                        command(["fit", model, HORSE, "--generations", "200", "--out", run],
                                cache, log=log)))  # fmt: skip
    rows.append(summary("report (after the fit)", command(["report", run], cache, log=log)))
    ev = ["evaluate", run / "best_model.toml", HORSE]
    rows.append(summary("evaluate (after the fit)", command(ev, cache, log=log)))
    traj = read_trajectory(HORSE)
    mask = np.array(traj.mask, bool)
    mask[300:360, list(traj.markers).index("HFL")] = False
    gappy = work / "trot_gap.csv"
    positions = np.where(mask[..., None], traj.positions, np.nan)
    write_trajectory(Trajectory(positions, mask, traj.markers, traj.rate), gappy)
    fill = ["fill", run / "best_model.toml", gappy, "--out", work / "filled.csv"]
    rows.append(summary("fill of one 60-frame gap (after the fit)", command(fill, cache, log=log)))
    return rows


def auto(work: Path, log) -> list[dict]:
    got = command(["auto", HORSE, "--out", work / "auto"], work / "cache-auto", log=log)
    marks = [(t, text.strip()) for t, text in got["lines"] if "compiling the cost" in text]
    rows = [summary("auto, bundled trot, cold", got)]
    starts = [t for t, _ in marks]  # the parent's clock: the child's, plus its start-up
    for i, t in enumerate(starts):
        stop = starts[i + 1] if i + 1 < len(starts) else got["wall"]
        misses = sum(
            1 for e in got["events"] if e["event"] == "cache_misses" and t <= e["at"] < stop
        )
        case = f"auto candidate {i + 1} (from its 'compiling' line): programs compiled"
        rows.append({"case": case, "programs_compiled": misses})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--old-python", help="python of an environment with an earlier version")
    parser.add_argument("--pairs", type=int, default=2)
    parser.add_argument("--only", default="paper,recommended,run7,auto")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--log", type=Path, help="every command's output, timestamped")
    args = parser.parse_args()
    cases = set(args.only.split(","))
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp, open(args.log or os.devnull, "w") as log:
        work = Path(tmp)
        if "paper" in cases:
            rows += paper(work, args.pairs, args.old_python, log)
        if "recommended" in cases:
            rows += recommended(work, log)
        if "run7" in cases:
            rows += run7(work, log)
        if "auto" in cases:
            rows += auto(work, log)
    news = [r["wall_s"] for r in rows if r.get("side") == "new"]
    olds = [r["wall_s"] for r in rows if r.get("side") == "old"]
    ratios = [round(o / n, 3) for n, o in zip(news, olds, strict=False)]
    result = {"load_average": os.getloadavg(), "rows": rows, "paper_old_over_new": ratios}
    for r in rows:
        print(json.dumps(r))
    if ratios:
        print(json.dumps({"paper old / new per pair": ratios}))
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
