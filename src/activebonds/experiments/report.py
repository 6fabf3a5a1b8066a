"""The report of ``reproduce`` / ``demo``: one self-contained HTML page for all experiments run,
built from the pieces of :mod:`activebonds.report` (figures, tables, canvas player)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..document import Marked
from ..identify.judge.verdict import verdict
from ..model import load_model
from ..report import animation, plots
from ..report.html import Figure, Section, Table, fmt, write_comparison_report
from ..report.predict import predict
from .paper import EXPERIMENTS, SERIES


def _histories(folder: Path, series: str) -> list[dict]:
    with np.load(folder / f"{series}_curves.npz") as z:
        best, median = z["best_rms_mm"], z["median_rms_mm"]
    return [{"best_rms_mm": b, "median_rms_mm": m} for b, m in zip(best, median, strict=True)]


def _baseline_rows(base: dict | None) -> list[list[str]]:
    """The rows every fit is judged against (same frames): zero force, exact least squares."""
    if not base:
        return []
    dash = ["-"] * 4
    return [
        [
            "zero force (constant velocity)",
            fmt(base["zero_force_fit_rms_mm"], 3),
            fmt(base["zero_force_test_rms_mm"], 3),
            "-",
            "-",
            *dash,
        ],
        [
            "exact least squares, standard bonds",
            fmt(base["lsq_standard_fit_rms_mm"], 3),
            fmt(base["lsq_standard_test_rms_mm"], 3),
            _verdict_cell(base["lsq_standard_test_rms_mm"], base),
            fmt(base["lsq_standard_free_run_rms_mm"], 3),
            *dash,
        ],
    ]


def _verdict_cell(model_mm, base: dict | None):
    """The verdict on the next frames' one-step RMS beside zero force's (red when not better)."""
    if not base:
        return "-"
    v = verdict(model_mm, base["zero_force_test_rms_mm"])
    word = v.word if v.better is not True else f"better by {v.gain_pct:.3g} %"
    return Marked(word, v.text()) if v.better is False else word


def _series_rows(c: dict, base: dict | None) -> list[list]:
    """A configuration's row per series: its medians over the seeds, the one-step verdict."""
    rows = []
    for s in SERIES:
        r = c["series"][s]
        rows.append(
            [
                s,
                f"{fmt(r['fit_rms_mm_median'], 3)} [{fmt(r['fit_rms_mm_iqr'][0], 3)}, "
                f"{fmt(r['fit_rms_mm_iqr'][1], 3)}]",
                fmt(r["one_step_rms_mm_median"], 3),
                _verdict_cell(r["one_step_rms_mm_median"], base),
                fmt(r["free_run_rms_mm_median"], 3),
                fmt(r.get("saturated_share_median", float("nan")), 2),
                fmt(r.get("near_zero_weight_share_median", float("nan")), 2),
                str(r["failed_evaluations"]),
                f"{r['seconds']:.0f} s",
            ]
        )
    return rows


def _config_section(
    name: str, exp, config: str, c: dict, folder: Path, n_seeds: int, base: dict | None = None
) -> Section:
    figs = folder / "figures"
    series = [plots.Series(label=s, histories=_histories(folder, s)) for s in SERIES]
    title = f"{name}: population {c['population']}, {c['generations']:,} generations"
    refs = []
    if base:
        refs = [
            ("zero force", base.get("zero_force_fit_rms_mm")),
            ("exact least squares, standard", base.get("lsq_standard_fit_rms_mm")),
            ("momentum floor", base.get("momentum_floor_mm")),
        ]
    conv = plots.convergence(series, figs / "convergence", title=title, references=refs)
    figures = [Figure(conv[0])]
    rows = _series_rows(c, base) + _baseline_rows(base)
    a, b = c["series"]["standard"]["test_frames"]
    floor = (
        ""
        if not base or base.get("momentum_floor_mm") is None
        else (
            f" No model of internal forces can go below {fmt(base['momentum_floor_mm'], 4)} mm on "
            "the fitted frames (momentum floor: linear and angular momentum are conserved)."
        )
    )
    table = Table(
        columns=[
            "series",
            "fit RMS mm, median [IQR]",
            f"one-step RMS mm, frames {a}-{b - 1}",
            "verdict (one step, those frames)",
            f"free-run RMS mm, frames {a}-{b - 1}",
            "saturated neurons",
            "near-zero weights",
            "failed evaluations",
            "wall time",
        ],
        rows=rows,
        caption=f"Medians over {n_seeds} seeds. Fit: frames {exp.fit_frames[0]}-"
        f"{exp.fit_frames[1] - 1}; the following frames were never seen by the fit. The last "
        "two rows are baselines on the same frames: the predictor with no force, and the "
        "exact bounded least-squares optimum of the standard model." + floor,
    )
    recording = exp.data().window(0, b)
    preds = []
    for s in SERIES:
        model = load_model(folder / f"best_{s}.toml")
        preds.append((f"{s} (best seed)", predict(model, recording, fit_frames=exp.fit_frames[1])))
        if s == "neural":
            figures.append(
                Figure(
                    plots.weight_heatmap(model, figs / "neural_weights")[0],
                    "Identified neural weights of the best neural model",
                )
            )
    gif = animation.write_gif(preds, figs / "animation.gif", title=f"{name} {config}")
    return Section(
        title=f"{name}: {config}",
        tables=[table],
        figures=figures,
        animation=animation.payload(preds, title=f"{name} {config}: recorded vs best models"),
        anchor=f"{name}-{config}",
        notes=[f"GIF of the animation: {gif.relative_to(folder.parent.parent)}"],
    )


def write_experiments_report(summaries: dict, out: Path) -> Path:
    sections = []
    for name, s in summaries.items():
        exp = EXPERIMENTS[name]
        for config, c in s["configs"].items():
            folder = out / name / config
            sections.append(
                _config_section(name, exp, config, c, folder, len(s["seeds"]), s.get("baselines"))
            )
    return write_comparison_report(
        out / "report.html",
        "activebonds: the paper's experiments, standard vs mechanical-neural bonds",
        sections,
        subtitle="Stanciulescu & Louchet (2000), reproduced with several seeds per series.",
    )
