"""Seconds ``activebonds baselines`` and ``activebonds structure`` take on a 41-marker body.

    python benchmarks/one_step_scale.py [--frames 200] [--tight] [--old REV] [--old-timeout S]
                                        [--blas-threads N] [--json out.json]

The case is :func:`body_model.body_case`: the bundled human walk's 41 markers, each a
particle joined by a spring-damper to its 6 nearest at frame 0 (138 bonds, 414 free genes),
``--frames`` frames simulated by activebonds at 60 Hz, 10 substeps, from a known truth. The
model file (every bond a candidate for ``structure``) and the recording are written to a
temporary folder, and each command runs in a fresh process, ``python -m activebonds.cli``,
timed from spawn to exit (imports and reading included), with its CPU time and peak memory.
``--tight`` narrows the rest lengths' bounds to +-3 % of the frame-0 distance, inside the
truth's +-10 %: the product constraints ``k lo <= k l0 <= k hi`` become active (92 of 138 in
the full model; ``structure`` then removes 23 bonds, ~3,000 solves).

"new" is this tree's ``src/``; ``--old REV`` also runs ``src/`` of a git revision (extracted
with ``git archive``), each command stopped after ``--old-timeout`` seconds (reported as
such), and compares the answers (largest relative difference of the least-squares values).
``--blas-threads N`` sets ``OPENBLAS_NUM_THREADS`` (and OMP/MKL) in the children: on a
2-core machine with another busy process, OpenBLAS's second thread waits for a core and
small factorisations slow down many times (measured 5.4 s with 1 thread, 46.6 s with 2 for
``baselines``).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))


def write_case(folder: Path, frames: int, tight: bool) -> dict:
    from activebonds.data import write_trajectory
    from body_model import body_case, body_model_toml

    bounds = {"rest_bounds": (0.97, 1.03)} if tight else {}
    model, traj = body_case(frames)
    data = folder / f"body{frames}.csv"
    write_trajectory(traj, data)
    (folder / "body.toml").write_text(body_model_toml(**bounds))
    (folder / "candidates.toml").write_text(body_model_toml(optional=True, **bounds))
    n_rows = (frames - 2) * traj.positions.shape[1] * traj.positions.shape[2]
    return {
        "markers": traj.positions.shape[1],
        "frames": frames,
        "bonds": int(model.topology.count("binary")),
        "genes": int(model.layout.n_genes),
        "least_squares_rows": n_rows,
        "tight_rest_bounds": tight,
        "data": str(data),
    }


def extract(rev: str, dest: Path) -> Path:
    archive = subprocess.Popen(
        ["git", "-C", str(REPO), "archive", rev, "src"], stdout=subprocess.PIPE
    )
    dest.mkdir(parents=True)
    subprocess.run(["tar", "-x", "-C", str(dest)], stdin=archive.stdout, check=True)
    if archive.wait() != 0:
        raise SystemExit(f"git archive {rev} failed")
    return dest / "src"


def run(src: Path, args: list[str], cwd: Path, timeout: float, threads: int | None) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    if threads:
        for key in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env[key] = str(threads)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "activebonds.cli", *args],
            cwd=cwd,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        return {"seconds": None, "timed_out_after_s": timeout}
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = {
        "seconds": round(wall, 2),
        "cpu_seconds": round(
            after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime, 2
        ),
        "peak_rss_mb": round(after.ru_maxrss / 1024),  # the largest child so far
        "exit_code": proc.returncode,
    }
    if proc.returncode != 0:
        out["stderr"] = proc.stderr[-2000:]
    else:
        out["stdout"] = proc.stdout
    return out


def commands(folder: Path, data: str, tag: str) -> dict[str, list[str]]:
    return {
        "baselines": ["baselines", "body.toml", data, "--json"],
        "structure": ["structure", "candidates.toml", data, "--out", f"structure_{tag}.toml"],
    }


def summary(result: dict) -> dict:
    out = {k: v for k, v in result.items() if k != "stdout"}
    text = result.get("stdout", "")
    if text.lstrip().startswith("{"):
        record = json.loads(text)
        out["least_squares_rms_mm"] = record.get("least_squares_rms_mm")
        out["least_squares_exact"] = record.get("least_squares_exact")
    elif text:
        out["last_line"] = text.strip().splitlines()[-1]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200)
    ap.add_argument("--tight", action="store_true")
    ap.add_argument("--old", default=None, help="also time src/ of this git revision")
    ap.add_argument("--old-timeout", type=float, default=1800.0)
    ap.add_argument("--blas-threads", type=int, default=None)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="one_step_scale-") as tmp:
        folder = Path(tmp)
        case = write_case(folder, args.frames, args.tight)
        data = case.pop("data")
        trees = {"new": REPO / "src"}
        if args.old:
            trees["old"] = extract(args.old, folder / "old")
        report = {
            "case": case,
            "command": " ".join(
                ["python", "benchmarks/one_step_scale.py", *(argv or sys.argv[1:])]
            ),
            "blas_threads": args.blas_threads,
            "load_average_before": os.getloadavg(),
            "old_revision": args.old,
            "runs": {},
        }
        raw = {}
        for tag, src in trees.items():
            timeout = args.old_timeout if tag == "old" else 3600.0
            for name, cmd in commands(folder, data, tag).items():
                print(f"{tag} {name} ...", file=sys.stderr, flush=True)
                raw[tag, name] = run(src, cmd, folder, timeout, args.blas_threads)
                report["runs"][f"{tag} {name}"] = summary(raw[tag, name])
                print(f"  {report['runs'][f'{tag} {name}']}", file=sys.stderr, flush=True)
        if ("old", "baselines") in raw and "stdout" in raw["old", "baselines"]:
            new = json.loads(raw["new", "baselines"]["stdout"])["least_squares"]
            old = json.loads(raw["old", "baselines"]["stdout"])["least_squares"]
            report["baselines_largest_relative_difference"] = max(
                abs(new[k] - old[k]) / max(abs(old[k]), 1e-300) for k in old
            )
        if ("old", "structure") in raw and "stdout" in raw["old", "structure"]:
            same = (folder / "structure_new.toml").read_text() == (
                folder / "structure_old.toml"
            ).read_text()
            report["structure_same_presence"] = _presence(folder / "structure_new.toml") == (
                _presence(folder / "structure_old.toml")
            )
            report["structure_files_identical"] = same
        report["load_average_after"] = os.getloadavg()
    text = json.dumps(report, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")
    return 0


def _presence(path: Path) -> list[bool]:
    import tomllib

    return [b.get("present", True) for b in tomllib.loads(path.read_text())["bond"]]


if __name__ == "__main__":
    sys.exit(main())
