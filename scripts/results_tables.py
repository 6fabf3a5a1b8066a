"""Write the results tables of the documentation from the JSON files in ``docs/results/``.

A page holds a marker pair::

    <!-- table: heldout_horse -->
    ...
    <!-- end table -->

and this script rewrites what lies between them from the JSON files, by the function of that
name in :data:`TABLES`, so a table and its JSON cannot disagree. Every figure of a generated
table is read from a JSON file; a figure that lives only in prose is not generated (the
details pages in ``docs/experiments/`` say which script printed it). Where the JSON has the
zero-force predictor's score, the table shows it beside the model's and says whether the
model beats it.

    python scripts/results_tables.py            # rewrite the stale pages
    python scripts/results_tables.py --check    # exit 1 and name the stale pages (CI)
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
RESULTS = DOCS / "results"
MARKER = re.compile(r"(<!-- table: ([\w-]+) -->\n)(.*?)(<!-- end table -->)", re.S)


class Results:
    """The JSON files of one folder, read once each: ``results("heldout_horse")``."""

    def __init__(self, folder: Path = RESULTS):
        self.folder = Path(folder)
        self._cache: dict[str, object] = {}

    def __call__(self, name: str):
        if name not in self._cache:
            self._cache[name] = json.loads((self.folder / f"{name}.json").read_text())
        return self._cache[name]


# ------------------------------------------------------------------------------ formatting


def sig(x: float | None, n: int = 3) -> str:
    """``x`` to ``n`` significant digits, never in exponent form above 1e-3."""
    if x is None:
        return "-"
    x = float(x)
    if not math.isfinite(x):
        return "none"
    if x == 0:
        return "0"
    if abs(x) < 1e-3:
        return f"{x:.{n - 1}e}"
    return f"{x:.{max(n - 1 - math.floor(math.log10(abs(x))), 0)}f}"


def num(x: float) -> str:
    """A count or a median of counts as it is (``5.0`` -> ``5``, ``13.5`` -> ``13.5``)."""
    return f"{float(x):g}"


def pct(fraction: float, n: int = 3, signed: bool = False) -> str:
    """A fraction as a percentage (``0.529`` -> ``52.9 %``)."""
    text = sig(100 * fraction, n)
    if signed and fraction > 0:
        text = "+" + text
    return f"{text} %"


def beats(model: float, zero: float, higher_is_better: bool = False) -> str:
    """Whether the model's score beats the zero-force predictor's, and by how much."""
    if higher_is_better:
        if model > zero:
            return "yes"
        return "no" if model < zero else "tie"
    if model < zero:
        return f"yes ({sig(100 * (1 - model / zero), 2)} % lower)"
    if model == zero:
        return "tie"
    return f"no ({sig(100 * (model / zero - 1), 2)} % higher)"


def rows(header: list[str], body: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in body]
    return "\n".join(lines) + "\n"


TABLES: dict[str, Callable[[Results], str]] = {}


def table(fn: Callable[[Results], str]) -> Callable[[Results], str]:
    TABLES[fn.__name__] = fn
    return fn


# ------------------------------------------------------------------------------ the tables


@table
def ground_hopper(results: Results) -> str:
    """The synthetic hopper's 14 parameters (ground_recovery.json, ..._smooth9.json)."""
    body = []
    for name, smooth in (("ground_recovery", "raw"), ("ground_recovery_smooth9", "`--smooth 9`")):
        by_noise: dict[float, list] = {}
        for run in results(name)["rows"]:
            by_noise.setdefault(run["noise_mm"], []).append(run)
        for noise, runs in sorted(by_noise.items()):
            relative = [
                (abs(v), k)
                for run in runs
                for k, v in run["errors"].items()
                if k != "ground.height"
            ]
            worst, which = max(relative)
            gravity = max(abs(run["errors"]["gravity"]) for run in runs)
            height = max(abs(run["errors"]["ground.height"]) for run in runs)
            body.append(
                [
                    f"{num(noise)} mm",
                    smooth,
                    ", ".join(str(run["seed"]) for run in runs),
                    " / ".join(sig(run["rms_mm"], 2) for run in runs),
                    pct(gravity, 2),
                    f"{pct(worst, 3)} ({which})",
                    f"{sig(1000 * height, 2)} mm",
                ]
            )
    return rows(
        [
            "marker noise",
            "restart states",
            "seeds",
            "fit RMS (mm)",
            "gravity error",
            "largest relative error (parameter)",
            "contact height error",
        ],
        body,
    )


@table
def horse_ground(results: Results) -> str:
    """The horse on the ground against the internal-only model (horse_ground.json)."""
    body = []
    for gait in results("horse_ground"):
        ground, internal = gait["models"]["ground"], gait["models"]["internal"]
        zero = gait["zero_force"]
        model = ground["held_out_one_step_rms_mm"]
        body.append(
            [
                gait["gait"],
                sig(model, 4),
                sig(internal["held_out_one_step_rms_mm"], 4),
                sig(zero["one_step_rms_mm"], 4),
                beats(model, zero["one_step_rms_mm"]),
                sig(gait["internal_floor_mm"], 3),
                f"{sig(ground['held_out_free_run_rms_mm'], 3)} / {sig(zero['free_run_rms_mm'], 3)}",
            ]
        )
    return rows(
        [
            "gait (held out 300-599)",
            "ground model, one step (mm)",
            "internal-only model",
            "zero force",
            "ground model beats zero force",
            "internal-force floor",
            "free-run RMS, ground model / zero force (mm)",
        ],
        body,
    )


def _worst(seeds: list[dict], estimate: str, kind: str, stat: str) -> float:
    return max(row[estimate][kind][stat] for row in seeds)


@table
def mujoco_recovery(results: Results) -> str:
    """MuJoCo's tendons: the one-step optimum against shooting (mujoco_recovery*.json,
    network_recovery.json); the worst seed of each figure."""
    body = []
    for name in ("mujoco_recovery", "mujoco_recovery_noise", "mujoco_recovery_noise_light"):
        record = results(name)
        args, seeds = record["args"], record["rows"]
        floor = (
            sig(_worst(seeds, "noise_floor", "damping", "median_pct"), 2) + " %"
            if seeds[0]["noise_floor"]
            else "-"
        )
        if all("zero_force_rms_mm" in row for row in seeds):
            fit = max(row["one_step_rms_mm"] for row in seeds)
            zero = min(row["zero_force_rms_mm"] for row in seeds)
            versus = f"{sig(fit, 2)} vs {sig(zero, 2)}: {beats(fit, zero).split(' (')[0]}"
        else:
            versus = "-"
        body.append(
            [
                f"4 masses, 6 tendons, {sig(args['rate'], 3)} Hz, {sig(args['seconds'], 2)} s, "
                f"dampings x{sig(args['damping_scale'], 2)}",
                f"{args['noise_mm']} mm",
                str(len(seeds)),
                f"{sig(_worst(seeds, 'one_step', 'stiffness', 'max_pct'), 3)} % / "
                f"{sig(_worst(seeds, 'one_step', 'damping', 'median_pct'), 3)} %",
                f"{sig(_worst(seeds, 'shooting', 'stiffness', 'max_pct'), 2)} % / "
                f"{sig(_worst(seeds, 'shooting', 'damping', 'median_pct'), 2)} %",
                floor,
                versus,
            ]
        )
    network = results("network_recovery")
    errors = network["errors_pct"]
    body.append(
        [
            f"{network['particles']} masses, {network['bonds']} tendons, {network['frames']} frames",
            f"{network['noise_mm']} mm",
            "1",
            "-",
            f"{sig(errors['stiffness']['max'], 2)} % / {sig(errors['damping']['median'], 2)} %",
            "-",
            f"shooting {sig(network['stage']['end_rms_mm'], 3)} (positions) vs "
            f"{sig(network['zero_force_rms_mm'], 3)} (one step): not the same measure",
        ]
    )
    return rows(
        [
            "MuJoCo recording",
            "noise",
            "seeds",
            "one-step optimum: stiffness max / damping median",
            "shooting: stiffness max / damping median",
            "Cramér-Rao floor, damping median",
            "one-step fit RMS vs zero force (mm)",
        ],
        body,
    )


@table
def shooting_speed(results: Results) -> str:
    """Wall times (shooting_tetra_loop.json, recommended.json, ttt_triangle.json)."""
    tetra = results("shooting_tetra_loop")["cases"]["tetra"]
    dense, structured = tetra["dense"], tetra["structured"]
    recommended = results("recommended")
    command = recommended["commands"]["recommended"]
    errors = command["errors"]
    ttt = {row["optimizer"]: row for row in results("ttt_triangle")["ttt"]}
    lsq = ttt["ours: exact least squares (--init lsq)"]
    cma = ttt["pycma CMA-ES"]
    frame = f"{tetra['frames']} frames, {tetra['genes']} parameters"
    return rows(
        ["task", "activebonds", "reference", "ratio"],
        [
            [
                f"one shooting stage, tetrahedron ({frame}), compilation included",
                f"{sig(structured['seconds'], 3)} s (by window)",
                f"{sig(dense['seconds'], 3)} s (dense Jacobian)",
                f"{sig(dense['seconds'] / structured['seconds'], 2)}x",
            ],
            [
                "the same, repeated (compilation cache warm)",
                f"{sig(structured['warm_seconds'], 3)} s",
                f"{sig(dense['warm_seconds'], 3)} s",
                f"{sig(dense['warm_seconds'] / structured['warm_seconds'], 3)}x",
            ],
            [
                f"the recommended shooting command, {recommended['frames']} frames, "
                f"{recommended['noise_mm']} mm noise",
                f"{sig(command['seconds'], 3)} s end to end; stiffness within "
                f"{sig(errors['stiffness']['max_pct'], 2)} %, damping median "
                f"{sig(errors['damping']['median_pct'], 2)} %",
                "-",
                "-",
            ],
            [
                "triangle, every parameter within 1 %, compilation included",
                f"{sig(lsq['wall_s'], 2)} s (exact least squares)",
                f"{sig(cma['wall_s'], 2)} s (pycma CMA-ES)",
                f"{sig(cma['wall_s'] / lsq['wall_s'], 2)}x",
            ],
        ],
    )


@table
def hopper_recovery(results: Results) -> str:
    """The hopper through contact and sticking (hopper_recovery*.json)."""
    body = []
    for record in (*results("hopper_recovery"), *results("hopper_recovery_smooth9")):
        errors = record["errors"]
        worst = max(errors, key=lambda k: abs(errors[k]))
        smooth = record["options"]["smooth"]
        body.append(
            [
                f"{num(record['noise_mm'])} mm",
                f"`--smooth {smooth}`" if smooth else "raw",
                f"{pct(errors[worst], 2, signed=True)} ({worst})",
                f"{pct(errors['leg.stiffness'], 2, signed=True)}",
                f"{pct(errors['ground.stiffness'], 2, signed=True)}",
                sig(record["stages"][-1]["end_rms_mm"], 2),
                f"{sig(record['seconds'], 2)} s",
            ]
        )
    return rows(
        [
            "marker noise",
            "search's restart states",
            "largest error (parameter)",
            "leg stiffness",
            "contact stiffness",
            "shooting RMS (mm)",
            "time",
        ],
        body,
    )


def _counted(passes: dict) -> str:
    return f"{sum(bool(v) for v in passes.values())} of {len(passes)}"


@table
def horse_gait(results: Results) -> str:
    """The gait family as auto finds it, held out (horse_gait.json: scripts/horse_gait.py)."""
    body = []
    for gait in results("horse_gait"):
        h = gait["held_out"]
        burn = h["burn_in"]
        body.append(
            [
                gait["gait"],
                gait["chosen"],
                f"{sig(h['one_step_mm'], 4)} vs {sig(h['zero_force_one_step_mm'], 4)}: "
                + beats(h["one_step_mm"], h["zero_force_one_step_mm"]),
                f"{sig(h['ahead_mm'], 3)} vs {sig(h['zero_force_ahead_mm'], 4)}: "
                + beats(h["ahead_mm"], h["zero_force_ahead_mm"]).split(" (")[0],
                f"{num(burn['model_within'])} vs {num(burn['template_within'])} "
                f"(zero force {num(burn['zero_force_within'])})",
                _counted(gait["passes"]),
            ]
        )
    return rows(
        [
            "gait (held out 300-599)",
            "variant chosen on 150-299",
            "one step, model vs zero force (mm)",
            f"{results('horse_gait')[0]['held_out']['ahead_frames']} frames ahead (mm)",
            "after a 10-frame burn-in, frames within 50 mm: model vs the mean gait",
            "targets met",
        ],
        body,
    )


@table
def horse_gait_tried(results: Results) -> str:
    """The gait models of the hand-written script (scripts/horse_gait.py at commit 950449b)
    beside what else was tried (horse_gait_950449b.json, ``tried``)."""
    body = []
    for gait in results("horse_gait_950449b"):
        chosen = gait["held_out"]
        variants = [("**chosen**", chosen), *gait["tried"].items()]
        for name, record in variants:
            h = record.get("held_out", record)
            body.append(
                [
                    gait["gait"],
                    name,
                    f"{sig(h['one_step_mm'], 4)}: "
                    + beats(h["one_step_mm"], chosen["zero_force_one_step_mm"]).split(" (")[0],
                    sig(h["ahead_mm"], 3),
                    num(h["frames_within_50mm"]),
                    num(h["body_frames_within_50mm"]),
                ]
            )
        body.append(
            [
                gait["gait"],
                "zero force",
                sig(chosen["zero_force_one_step_mm"], 4),
                sig(chosen["zero_force_ahead_mm"], 4),
                num(chosen["zero_force_frames_within_50mm"]),
                num(chosen["zero_force_body_frames_within_50mm"]),
            ]
        )
    return rows(
        [
            "gait",
            "model (held out 300-599)",
            "one step (mm): beats zero force",
            "10 ahead (mm)",
            "frames within 50 mm",
            "body frames",
        ],
        body,
    )


@table
def horse_drive(results: Results) -> str:
    """The trot with a clock-driven rhythm (horse_drive.json)."""
    record = results("horse_drive")
    zero = record["zero_force"]
    names = {"one-step": "one-step fit", "refined": "then shooting, horizon 30"}
    body = []
    for name, model in record["models"].items():
        one = model["held_out_one_step_rms_mm"]
        body.append(
            [
                names.get(name, name),
                f"{sig(one, 4)} vs {sig(zero['held_out_one_step_rms_mm'], 4)}: "
                + beats(one, zero["held_out_one_step_rms_mm"]),
                f"{sig(model['held_out_free_run_rms_mm'], 3)} vs "
                f"{sig(zero['held_out_free_run_rms_mm'], 4)}",
                f"{num(model['held_out_frames_within_50mm'])} vs "
                f"{num(zero['held_out_frames_within_50mm'])}",
            ]
        )
    return rows(
        [
            "drive fitted by",
            "held-out one step vs zero force (mm)",
            "free-run RMS vs zero force (mm)",
            "frames within 50 mm",
        ],
        body,
    )


@table
def springs_structure(results: Results) -> str:
    """The NRI springs: edge accuracy by noise and smoothing (springs_structure.json)."""
    record = results("springs_structure")
    windows = sorted({row["smooth_window"] for row in record["rows"]})
    body = []
    for noise in sorted({row["noise"] for row in record["rows"]}):
        cells = [sig(noise, 1) if noise else "0"]
        for window in windows:
            row = next(
                r for r in record["rows"] if r["noise"] == noise and r["smooth_window"] == window
            )
            cells.append(
                f"{sig(row['edge_accuracy_percent'], 3)} % "
                f"({row['graphs_all_right']} / {row['trajectories']} graphs)"
            )
        body.append(cells)
    header = ["observation noise"] + [f"smoothed over {w} frames" if w else "raw" for w in windows]
    body.append(
        [f"NRI, supervised, trained on noiseless data: {record['nri_supervised_percent']} %"]
        + [""] * len(windows)
    )
    return rows(header, body)


@table
def horse_structure(results: Results) -> str:
    """The horse's pruned complete graph (horse_structure.json)."""
    body = []
    for gait in results("horse_structure")["results"]:
        models = gait["models"]
        pruned = models["pruned"]
        zero = gait["zero_force"]["held_out_rms_mm"]
        every = models["candidates (all present)"]
        body.append(
            [
                gait["gait"],
                f"{pruned['bonds']} of {every['bonds']}",
                sig(pruned["held_out_rms_mm"], 4),
                sig(every["held_out_rms_mm"], 4),
                sig(models["hand-written (as the candidates)"]["held_out_rms_mm"], 4),
                sig(models["hand-written (file's parametrisation)"]["held_out_rms_mm"], 4),
                sig(zero, 4),
                beats(pruned["held_out_rms_mm"], zero),
            ]
        )
    return rows(
        [
            "gait (held out 300-599, one step, mm)",
            "bonds kept",
            "pruned",
            "every candidate",
            "hand-written, parametrised as the candidates",
            "hand-written, its own parameters",
            "zero force",
            "pruned beats zero force",
        ],
        body,
    )


@table
def heldout_horse(results: Results) -> str:
    """`auto` on the held-out horse (heldout_horse.json)."""
    body = []
    for gait in results("heldout_horse")["results"]:
        a = gait["auto"]
        pairs = zip(a["per_marker_mm"], a["zero_force_per_marker_mm"], strict=True)
        ratios = [m / z for m, z in pairs]
        worst = max(range(len(ratios)), key=ratios.__getitem__)
        body.append(
            [
                gait["gait"],
                f"{sig(a['held_out_rms_mm'], 4)} vs {sig(a['zero_force_rms_mm'], 4)}: "
                + beats(a["held_out_rms_mm"], a["zero_force_rms_mm"]),
                f"{gait['markers'][worst]}, {ratios[worst]:.3f} x zero force",
                f"{sig(a['ahead']['model_mm'], 3)} vs {sig(a['ahead']['zero_force_mm'], 4)}: "
                + beats(a["ahead"]["model_mm"], a["ahead"]["zero_force_mm"]).split(" (")[0],
                f"{num(a['frames_within_50mm'])} vs {num(a['zero_force_frames_within_50mm'])}",
                f"{num(a['body_frames_within_50mm'])} vs "
                f"{num(a['body_zero_force_frames_within_50mm'])}",
            ]
        )
    return rows(
        [
            "gait (fitted 0-299, held out 300-599)",
            "one step, model vs zero force (mm)",
            "worst marker",
            "10 frames ahead (mm)",
            "frames within 50 mm",
            "body markers' frames within 50 mm",
        ],
        body,
    )


@table
def uncertainty_coverage(results: Results) -> str:
    """Coverage of the 95 % intervals (uncertainty_coverage.json)."""
    record = results("uncertainty_coverage")
    coverage = [p["coverage"] for p in record["per_parameter"].values()]
    return rows(
        [
            "data",
            "intervals",
            "contain the truth",
            "fits that reached the noise level",
            "their intervals contain the truth",
            "per parameter",
        ],
        [
            [
                f"{record['datasets']} noisy triangles ({record['frames']} frames, "
                f"{record['noise_mm']} mm)",
                str(record["intervals"]),
                pct(record["pooled_coverage"], 3),
                f"{record['fits_at_noise_level']} of {record['datasets']}",
                pct(record["coverage_of_those"], 3),
                f"{pct(min(coverage), 2)} to {pct(max(coverage), 2)}",
            ]
        ],
    )


@table
def gaps(results: Results) -> str:
    """Gap fills against the labs' fills (gaps_gait_springs.json for the horses' gait model,
    gaps.json for the human walk's spring body)."""
    body = []
    sources = [
        ("gaps_gait_springs", "gait model + springs", ("horse-trot", "horse-walk")),
        ("gaps", "spring body", ("human-walk",)),
    ]
    for name, model_name, recordings in sources:
        record = results(name)["recordings"]
        for recording in recordings:
            for length, medians in sorted(
                record[recording]["by_length"].items(), key=lambda kv: int(kv[0])
            ):
                m = {k: v["median_mm"] for k, v in medians.items()}
                best = min(m, key=m.get)
                body.append(
                    [
                        recording,
                        length,
                        model_name,
                        sig(m["model"], 3),
                        sig(m["model+pca"], 3),
                        sig(m["spline"], 3),
                        sig(m["pca"], 3),
                        f"{m['model'] / m['spline']:.2f} / {m['model'] / m['pca']:.2f}",
                        best,
                    ]
                )
    return rows(
        [
            "recording",
            "gap (frames)",
            "model",
            "model fill (mm)",
            "with `--prior pca`",
            "spline",
            "PCA",
            "model / spline, / PCA",
            "best",
        ],
        body,
    )


@table
def gaps_kept(results: Results) -> str:
    """Gap fills by the model ``auto`` keeps on the other half (gaps_kept.json), beside the
    labs' fills, and the fill's stated uncertainty against its error."""
    body = []
    record = results("gaps_kept")["recordings"]
    for recording, found in record.items():
        for length, medians in sorted(found["by_length"].items(), key=lambda kv: int(kv[0])):
            m = {k: v["median_mm"] for k, v in medians.items()}
            cover = found["coverage"][length]
            body.append(
                [
                    Path(recording).name,
                    length,
                    sig(m["model"], 3),
                    sig(m["spline"], 3),
                    sig(m["pca"], 3),
                    f"{m['model'] / m['spline']:.2f} / {m['model'] / m['pca']:.2f}",
                    f"{cover['median_error_over_stated']:.2f} / "
                    f"{100 * cover['within_twice_stated']:.0f} %",
                ]
            )
    return rows(
        [
            "recording",
            "gap (frames)",
            "kept model's fill (mm)",
            "spline",
            "PCA",
            "model / spline, / PCA",
            "error / stated (median), within 2x stated",
        ],
        body,
    )


# ------------------------------------------------------------------------------ the pages


def render(text: str, results: Results) -> str:
    """The page with every marked table written from the JSON files."""

    def write(match: re.Match) -> str:
        name = match.group(2)
        if name not in TABLES:
            raise KeyError(f"no table named {name!r} (known: {', '.join(sorted(TABLES))})")
        return match.group(1) + TABLES[name](results) + match.group(4)

    return MARKER.sub(write, text)


def pages(docs: Path = DOCS) -> list[Path]:
    """The pages that hold at least one marked table."""
    return sorted(p for p in docs.rglob("*.md") if MARKER.search(p.read_text()))


def stale(docs: Path = DOCS, results_dir: Path = RESULTS) -> list[Path]:
    """The pages whose marked tables differ from what the JSON files give."""
    results = Results(results_dir)
    return [p for p in pages(docs) if render(p.read_text(), results) != p.read_text()]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a page is stale")
    parser.add_argument("--docs", type=Path, default=DOCS)
    parser.add_argument("--results", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    behind = stale(args.docs, args.results)
    if args.check:
        for page in behind:
            print(
                f"{page.relative_to(args.docs.parent)}: a table differs from its JSON; "
                "run python scripts/results_tables.py",
                file=sys.stderr,
            )
        return 1 if behind else 0
    results = Results(args.results)
    for page in behind:
        page.write_text(render(page.read_text(), results))
        print(f"wrote {page.relative_to(args.docs.parent)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
