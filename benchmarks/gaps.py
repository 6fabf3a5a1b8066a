"""The gap benchmark: a marker removed for 10, 30 and 60 frames, filled by a fitted model and by
the fills labs use (linear, cubic spline, Gløersen & Federolf's PCA), against the removed
samples.

    python benchmarks/gaps.py --json gaps.json                       # the full run
    python benchmarks/gaps.py --positions 2 --lengths 10,30 --recordings horse-trot --json small.json

On each bundled recording (``activebonds datasets``: horse-trot, horse-walk, human-walk), for
each gap length, ``--positions`` gaps (default 20) are drawn (seed ``--seed``): a marker and a
start where that marker is present over the gap and one frame either side, half of them in the
first half of the recording and half in the second. Every method fills the same gaps, one at a
time, each from the recording with only that gap removed (the recording's own gaps stay as they
are and are not filled). The error of a gap: the RMS of the 3-D distance between the filled and
the removed samples, in mm.

The model: a spring body of the recording's markers (``benchmarks/body_model.py``: every pair of
the 7 horse markers, or each of the 41 human markers to its 6 nearest; mass 1 each, no
gravity; or ``--model auto``), its stiffness, rest lengths and dampings identified by the exact one-step least
squares (``identify.lsq.least_squares``) on the half of the recording that does not hold the
gap: two fits per recording, each filling the other half's gaps. The model fill is
``activebonds fill --method model`` (``identify.fill.model_fill``, ``--context`` 30 frames,
``--horizon`` 1, the continuity weight chosen from the context: ``identify.fill.continuity_weight``;
each gap's row records it). ``model+pca`` is the same fill with ``--prior pca``: each stretch
fitted again with the PCA fill of the missing samples (its positions and its frame-to-frame
steps) as soft observations, weighed by the PCA fill's cross-validated error against the
first fit's scaled residual SD (``identify.fill.pca_prior``); one call gives both, ``model``
being its first fit.

``--model gait`` replaces the spring body by the gait family's model of the other half
(:mod:`activebonds.identify.discover.gait`: an anchor and a periodic force per marker, the
drive's phase entrained by the body's most periodic signal; the variant chosen on that half,
:func:`gait_half`); its fill tracks the phase along the recording
(``identify.fill.fill_phases``). (Before issue 44 it was the hand-written
``scripts/horse_gait.py`` of commit 950449b, which ``gaps_gait.json`` and
``gaps_gait_springs.json`` were run with.)

``--model kept`` replaces it by the model ``activebonds auto`` keeps on the other half
(``auto RECORDING --frames A:B --held-out 0.05``, :func:`kept_half`): a gait where the
half is rhythmic and the gait judges best. ``--recordings`` also takes files (any format).

``--model auto`` replaces the spring body by ``activebonds auto``'s linear model of the half
(complete graph and an anchor per marker, the variant chosen on the half's validation tail,
exact least squares: :func:`auto_half`). ``--fitted-on same`` fits each half's model on the
gaps' own half: gaps the model has seen, the set on which a design is chosen before the
benchmark is run (the step prior of ``--prior pca`` was chosen so, ``--seed 1``).

The figures in docs/experiments/gaps.md were run one thread per process (the fill's solves are
small; under a second process's load XLA's and OpenBLAS's threads wait on each other)::

    OPENBLAS_NUM_THREADS=1 XLA_FLAGS=--xla_cpu_multi_thread_eigen=false python benchmarks/gaps.py ...

JSON out: the settings, per recording the two fits (frames, one-step RMS mm), every gap
(marker, start, length, error per method), and summaries: per method and length the median,
mean and 90th percentile error, and per marker the median.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))

METHODS = ("model", "model+pca", "spline", "linear", "pca")
MODEL_METHODS = ("model", "model+pca")
RECORDINGS = ("horse-trot", "horse-walk", "human-walk")


def recording_path(name: str) -> Path:
    """A bundled recording's file, or ``name`` itself where it is a file (any format)."""
    from activebonds.data.bundled import dataset

    return Path(name) if Path(name).is_file() else Path(dataset(name).path)


def recording(name: str):
    from activebonds.data import read_trajectory

    return read_trajectory(recording_path(name))


# auto's held-out share on a half (its own tail, at least 10 frames): the half is the model's
# to fit, as the other methods' fits have all of it
KEPT_HELD_OUT = 0.05


def kept_half(name: str, traj, frames: tuple[int, int]):
    """The model ``activebonds auto`` keeps on ``frames`` alone (``auto RECORDING --frames
    A:B --held-out`` :data:`KEPT_HELD_OUT`, its other options the defaults: it fits all but
    its smallest held-out tail of them and keeps the candidate its rule judges best,
    :mod:`activebonds.auto`); (model, its one-step RMS mm on ``frames``)."""
    import tempfile

    from activebonds import auto
    from activebonds.identify.judge.predictions import one_step, rms_mm
    from activebonds.identify.rundir import RunDir
    from activebonds.model import load_model

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "auto"
        outcome = auto.run(
            recording_path(name), out, auto.Options(frames=frames, held_out=KEPT_HELD_OUT),
            say=lambda line: None,
            verbose=False,
        )  # fmt: skip
        kept = out / outcome.state["steps"]["fit"]["run"]
        model = load_model(RunDir(kept).best_model_path)
    print(f"{name} {frames[0]}:{frames[1]}: auto kept {kept.name}", flush=True)
    part = traj.select(list(model.markers)).window(*frames)
    one = one_step(model, np.asarray(part.positions), part.dt)
    return model, float(np.sqrt(np.nanmean(np.square(rms_mm(one, part.positions)))))


def spring_model(name: str, traj):
    from activebonds.model import loads_model
    from body_model import body_model_toml, horse_toml

    text = body_model_toml(traj) if name == "human-walk" else horse_toml(traj)
    return loads_model(text, f"<{name} springs>")


def auto_half(traj, frames: tuple[int, int]):
    """``activebonds auto``'s linear model of ``frames`` (issue 25, without its evolution
    strategy): the scaffold's complete graph of the markers plus an anchor per marker
    (``identify.scaffold``, no gravity), the variant (masses, anchors, BIC-decided or not)
    chosen on the frames' validation tail and solved by the exact least squares on all of
    them (``identify.structure_choice``); (model, its one-step RMS mm on ``frames``)."""
    from activebonds.identify.discover.scaffold import scaffold
    from activebonds.identify.discover.structure_choice import Variant, choose, decide
    from activebonds.identify.judge.predictions import one_step, rms_mm
    from activebonds.model import build, loads_model

    text = scaffold(traj, frames=frames, complete=True, gravity=False).text
    base = loads_model(text, "<auto scaffold>")
    choice = choose(base, traj, frames)
    variant = choice.chosen if choice is not None else Variant()
    model = build(decide(base, traj, frames, variant).spec)
    part = traj.select(list(model.markers)).window(*frames)
    one = one_step(model, np.asarray(part.positions), part.dt)
    return model, float(np.sqrt(np.nanmean(np.square(rms_mm(one, part.positions)))))


def gait_half(name: str, traj, frames: tuple[int, int]):
    """The gait family's model of ``frames`` alone (:func:`activebonds.auto.gait.choose`: its
    rhythm, signals and variant found on them, the variant fitted on their first half and
    judged on the second, solved on all of them); (model, its one-step RMS mm on
    ``frames``). SystemExit where they are not rhythmic."""
    from activebonds.auto.gait import choose
    from activebonds.identify.judge.predictions import one_step, rms_mm
    from activebonds.model import build

    chosen = choose(traj, frames, 10, say=lambda line: None)
    if chosen is None:
        raise SystemExit(f"--model gait: {name} {frames[0]}:{frames[1]} is not rhythmic")
    model = build(chosen.spec)
    part = traj.window(*frames)
    one = one_step(model, np.asarray(part.positions), part.dt)
    return model, float(np.sqrt(np.nanmean(np.square(rms_mm(one, part.positions)))))


def fit_half(model, traj, frames: tuple[int, int]):
    """The model's linear genes by exact least squares on ``frames`` (one step, horizon 1)."""
    from activebonds.identify.costs.windows import make_windows
    from activebonds.identify.solvers.lsq import least_squares

    part = traj.select(list(model.markers)).window(*frames)
    fit = least_squares(model, make_windows(part.positions, part.mask, part.dt, 1))
    return model.with_genome(fit.genome), fit.rms_mm


def draw_gaps(traj, length: int, count: int, rng) -> list[tuple[int, int, int]]:
    """(half, marker, start): ``count`` gaps, half in each half of the recording."""
    n = traj.n_frames
    mid = n // 2
    out = []
    for half, (lo, hi) in enumerate(((0, mid), (mid, n))):
        choices = [
            (m, s)
            for m in range(traj.n_markers)
            for s in range(max(lo, 1), min(hi, n - 1) - length + 1)
            if traj.mask[s - 1 : s + length + 1, m].all()
        ]
        want = count // 2 + (count % 2 if half == 0 else 0)
        if not choices:
            continue
        picks = rng.choice(len(choices), size=min(want, len(choices)), replace=False)
        out += [(half, *choices[i]) for i in sorted(picks)]
    return out


def fill_one(method, model, traj, marker: int, start: int, length: int, context, horizon):
    """The filled samples [length, D] of one removed gap (``model+pca``: a dict of both
    model fills, with and without the prior, from one call)."""
    from activebonds.data.fill import Gap, fill_baseline, plan_fill

    positions = np.array(traj.positions)
    mask = np.array(traj.mask)
    mask[start : start + length, marker] = False
    positions[~mask] = np.nan
    gappy = traj.with_positions(positions, mask)
    names = list(model.markers)
    plan = plan_fill(gappy, names)
    column = names.index(traj.markers[marker])
    gap = Gap(column, traj.markers[marker], start, start + length)
    others = tuple(
        dataclasses.replace(g, reason=g.reason or "not tested")
        for g in plan.gaps
        if (g.column, g.start) != (column, start)
    )
    plan = dataclasses.replace(plan, gaps=(gap, *others))
    extra = {}
    if method in MODEL_METHODS:
        from activebonds.identify.gaps.fill import model_fill

        prior = "pca" if method == "model+pca" else None
        found = model_fill(model, plan, context=context, horizon=horizon, prior=prior)
        seg = found.segments[0]
        extra = {"continuity": seg.continuity, "steps": seg.steps}
        if prior is not None:
            extra["prior_weight"] = seg.prior_weight
            both = {"model": found.pure, "model+pca": found.values}
            return {m: v[start : start + length, column] for m, v in both.items()}, extra
        values = found.values
        # the fill's stated uncertainty of the gap (3-D SD per sample): its RMS, mm
        extra["stated_mm"] = float(np.sqrt(np.mean(np.square(found.uncertainty[0]))) * 1000.0)
    else:
        values = fill_baseline(method, plan.positions, plan.mask, plan.local())
    return values[start : start + length, column], extra


def summary(errors: list[float]) -> dict:
    e = np.asarray(errors, np.float64)
    e = e[np.isfinite(e)]
    if not e.size:
        return {"n": 0}
    return {
        "n": int(e.size),
        "median_mm": float(np.median(e)),
        "mean_mm": float(np.mean(e)),
        "p90_mm": float(np.percentile(e, 90)),
    }


def _coverage(gaps: list[dict]) -> dict:
    """The model fill's stated uncertainty against its error, over gaps of one length: the
    median of error / stated (both RMS over the gap, 3-D; about 1 where the uncertainty is
    right) and the share of gaps whose error is within twice the stated one."""
    pairs = [
        (g["error_mm"]["model"], g["stated_mm"])
        for g in gaps
        if "stated_mm" in g and "model" in g["error_mm"] and g["stated_mm"] > 0
    ]
    if not pairs:
        return {"n": 0}
    ratio = np.asarray([e / s for e, s in pairs])
    return {
        "n": len(pairs),
        "median_error_over_stated": float(np.median(ratio)),
        "within_twice_stated": float(np.mean(ratio <= 2.0)),
        "median_stated_mm": float(np.median([s for _, s in pairs])),
    }


def summarize(traj, fits, gaps, args) -> dict:
    """A recording's result: its fits, its gaps, the summaries per length and per marker."""
    lengths = sorted({g["length"] for g in gaps})
    by_length = {
        str(length): {
            m: summary([g["error_mm"][m] for g in gaps if g["length"] == length])
            for m in args.methods
        }
        for length in lengths
    }
    by_marker = {
        str(length): {
            marker: {
                m: float(
                    np.median(
                        [
                            g["error_mm"][m]
                            for g in gaps
                            if g["length"] == length and g["marker"] == marker
                        ]
                    )
                )
                for m in args.methods
            }
            for marker in sorted({g["marker"] for g in gaps if g["length"] == length})
        }
        for length in lengths
    }
    coverage = {
        str(length): _coverage([g for g in gaps if g["length"] == length]) for length in lengths
    }
    return {
        "frames": traj.n_frames,
        "markers": list(traj.markers),
        "fits": fits,
        "by_length": by_length,
        "coverage": coverage,
        "by_marker": by_marker,
        "gaps": gaps,
    }


def run(args) -> dict:
    out = {
        "settings": {
            "recordings": args.recordings,
            "lengths": args.lengths,
            "positions": args.positions,
            "methods": args.methods,
            "seed": args.seed,
            "context": args.context,
            "horizon": args.horizon,
            "model": args.model,
            "fitted_on": args.fitted_on,
            "command": " ".join(sys.argv),
        },
        "recordings": {},
    }
    for r_index, name in enumerate(args.recordings):
        traj = recording(name)
        base = spring_model(name, traj) if args.model == "springs" else None
        mid = traj.n_frames // 2
        halves = ((0, mid), (mid, traj.n_frames))
        models, fits = [], []
        for h, frames in enumerate(halves):
            started = time.time()
            # the model fitted on the other half: it never saw the gaps of this one
            # (--fitted-on same: on the gaps' own half, the set to choose a design on)
            other = halves[1 - h] if args.fitted_on == "other" else frames
            if args.model == "auto":
                model, rms = auto_half(traj, other)
            elif args.model == "kept":
                model, rms = kept_half(name, traj, other)
            elif args.model == "gait":
                model, rms = gait_half(name, traj, other)
            else:
                model, rms = fit_half(base, traj, other)
            models.append(model)
            fits.append(
                {
                    "fills_frames": f"{frames[0]}:{frames[1]}",
                    "fitted_on": f"{other[0]}:{other[1]}",
                    "one_step_rms_mm": rms,
                    "seconds": round(time.time() - started, 2),
                }
            )
        gaps = []
        fused = "model+pca" in args.methods
        for length in args.lengths:
            # the recording's place among the bundled ones: a run of a subset draws the same gaps
            index = RECORDINGS.index(name) if name in RECORDINGS else r_index
            rng = np.random.default_rng([args.seed, index, length])
            for half, marker, start in draw_gaps(traj, length, args.positions, rng):
                truth = traj.positions[start : start + length, marker]
                row = {
                    "marker": traj.markers[marker],
                    "start": start,
                    "length": length,
                    "error_mm": {},
                    "seconds": {},
                }
                done = {}
                for method in args.methods:
                    t0 = time.time()
                    if method not in done:
                        # with the prior, one call gives both model fills
                        call = "model+pca" if method == "model" and fused else method
                        got, extra = fill_one(
                            call,
                            models[half],
                            traj,
                            marker,
                            start,
                            length,
                            args.context,
                            args.horizon,
                        )
                        done.update(got if isinstance(got, dict) else {method: got})
                        row.update(extra)
                    err = np.sqrt(np.mean(np.sum((done[method] - truth) ** 2, axis=-1))) * 1000.0
                    row["error_mm"][method] = float(err)
                    row["seconds"][method] = round(time.time() - t0, 3)
                gaps.append(row)
                print(
                    f"{name} {row['marker']} {start}:{start + length} "
                    + " ".join(f"{m} {e:.3g}" for m, e in row["error_mm"].items()),
                    flush=True,
                )
                out["recordings"][name] = summarize(traj, fits, gaps, args)
                if args.json is not None:  # a partial result after every gap
                    args.json.write_text(json.dumps(out, indent=2) + "\n")
        out["recordings"][name] = summarize(traj, fits, gaps, args)
    return out


def table(result: dict) -> str:
    """Markdown: per recording and gap length, the gaps, each method's median error (mm), the
    winner, and each model fill's median over the spline's and over the PCA fill's."""
    methods = result["settings"]["methods"]
    ours = [m for m in MODEL_METHODS if m in methods]
    ratios = [(m, o) for m in ours for o in ("spline", "pca") if o in methods]
    lines = [
        "| recording | gap (frames) | gaps | "
        + " | ".join(methods)
        + " | best | "
        + " | ".join(f"{m} / {o}" for m, o in ratios)
        + " |"
    ]
    lines.append("|" + " --- |" * (4 + len(methods) + len(ratios)))
    for name, rec in result["recordings"].items():
        for length, per in rec["by_length"].items():
            med = {m: per[m].get("median_mm", float("nan")) for m in methods}
            cells = [f"{med[m]:.3g}" if per[m].get("n") else "—" for m in methods]
            best = min(methods, key=lambda m: med[m] if med[m] == med[m] else float("inf"))
            ratio = [f"{med[m] / med[o]:.2f}" for m, o in ratios]
            n = per[methods[0]].get("n", 0)
            lines.append(
                f"| {name} | {length} | {n} | "
                + " | ".join(cells)
                + f" | {best} | "
                + " | ".join(ratio)
                + " |"
            )
    return "\n".join(lines)


def merge(paths: list[Path]) -> dict:
    """One result from several runs' JSON (each recording from the last run that has it); the
    runs' settings kept in ``runs``."""
    runs = [json.loads(Path(p).read_text()) for p in paths]
    out = {"settings": dict(runs[0]["settings"]), "runs": [], "recordings": {}}
    for run_ in runs:
        out["runs"].append(
            {
                **run_["settings"],
                "seconds": run_.get("seconds"),
                "recordings_run": list(run_["recordings"]),
            }
        )
        out["recordings"].update(run_["recordings"])
    out["settings"]["recordings"] = list(out["recordings"])
    out["settings"]["command"] = [r["command"] for r in out["runs"]]
    return out


def main() -> None:
    from activebonds.runtime import fast_cpu_flags

    fast_cpu_flags()
    import jax

    jax.config.update("jax_enable_x64", True)
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--recordings", default=",".join(RECORDINGS))
    p.add_argument("--lengths", default="10,30,60")
    p.add_argument("--positions", type=int, default=20)
    p.add_argument("--methods", default=",".join(METHODS))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--context", type=int, default=30)
    p.add_argument("--horizon", type=int, default=1)
    p.add_argument(
        "--fitted-on",
        choices=("other", "same"),
        default="other",
        help="the half the model is fitted on: the other one (the benchmark) or the gaps' own "
        "(gaps the model has seen: a set to choose a design on, not to report)",
    )
    p.add_argument(
        "--model",
        choices=("springs", "auto", "gait", "kept"),
        default="springs",
        help="the fitted model: the spring body, auto's linear model (complete graph and "
        "anchors, issue 25), the gait model (anchors, periodic forces, an entrained "
        "phase: the gait family found on the other half), or the model "
        "activebonds auto keeps with its default options on the other half (kept)",
    )
    p.add_argument("--json", type=Path, default=None)
    p.add_argument(
        "--merge", type=Path, nargs="+", default=None, help="join these runs' JSON into --json"
    )
    p.add_argument("--table", type=Path, default=None, help="print the table of this JSON")
    args = p.parse_args()
    if args.table is not None:
        print(table(json.loads(args.table.read_text())))
        return
    if args.merge:
        result = merge(args.merge)
        if args.json is not None:
            args.json.write_text(json.dumps(result, indent=2) + "\n")
        print(table(result))
        return
    args.recordings = args.recordings.split(",")
    args.lengths = [int(x) for x in args.lengths.split(",")]
    args.methods = args.methods.split(",")
    started = time.time()
    result = run(args)
    result["seconds"] = round(time.time() - started, 1)
    print("median RMS error of the removed samples (mm):")
    print(table(result))
    if args.json is not None:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
