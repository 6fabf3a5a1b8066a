"""A sweep's summary: one row per fit, as OUT/summary.csv and a self-contained OUT/summary.html.

Each row is measured the way ``fit``'s summary and ``report`` measure one run, with their
functions: the fit's RMS error (status.json, as the run stored it), the zero-force
(constant-velocity) baseline over the same one-step terms of every fitted recording
(:func:`~activebonds.identify.judge.baselines.zero_force_rms_mm_of`), the free-run RMS and the
frames a free run stays within 50 mm (:func:`~activebonds.identify.judge.metrics.window_metrics` on the
first fitted recording), and the identified value of every free parameter (best_model.toml).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from pathlib import Path

from ..atomic import write_text_atomic
from ..document import Marked, Section, Table
from ..errors import InputError
from ..identify import stages
from ..identify.judge.metrics import THRESHOLD_MM, censored_text
from ..identify.judge.verdict import EXPLAINS_NOT
from ..report.html import render
from ..report.runs import load_run
from .manifest import Job
from .outcome import Outcome

FRAMES_WITHIN = f"frames_within_{THRESHOLD_MM:g}mm"
NOT_MEASURES = ("status", "seed", "generations", "parameters")  # a row's other entries
MEASURES = (  # (CSV column, HTML heading)
    ("rms_mm", "RMS error (mm)"),
    ("zero_force_rms_mm", "zero force RMS (mm)"),
    ("free_run_rms_mm", "free-run RMS (mm)"),
    (FRAMES_WITHIN, f"frames within {THRESHOLD_MM:g} mm (median)"),
    ("frames_within_censored", "censored"),
)


def row(run: Path) -> dict:
    """The numbers of the run directory ``run``: status, seed, generations done, the fit's
    RMS error, the columns each post-fit stage tabulates of its record
    (:mod:`activebonds.identify.stages`) and ``parameters`` (name -> identified value); what
    cannot be measured (no run yet, no best model, a stage that did not run) is left out."""
    try:
        record = load_run(run)
    except InputError:
        return {}
    st, s = record.status, record.settings
    out: dict = {
        "status": st.get("status", "unknown"),
        "seed": s.seed,
        "generations": int(st.get("generation", len(record.history.get("generation", [])))),
        "rms_mm": st.get("best_rms_mm"),
    }
    for stage in stages.stages():
        if stage.name in record.records:
            out.update(stage.columns(record.records[stage.name]))
    if record.has_best:
        out["parameters"] = {g.name: float(g.value) for g in record.model.layout.genes}
    return out


def varied_settings(jobs: Sequence[Job]) -> list[str]:
    """The settings that differ between the fits (besides the seed and the generations,
    columns of their own), in FitSettings' order."""
    dumps = [j.settings.model_dump(mode="json", exclude={"seed", "generations"}) for j in jobs]
    return [k for k in dumps[0] if any(d[k] != dumps[0][k] for d in dumps)] if dumps else []


def table(jobs: Sequence[Job], outcomes: Sequence[Outcome]) -> tuple[list[str], list[list]]:
    """Columns and rows, one per fit in the manifest's order: name, status, seed,
    generations, the settings that differ, :data:`MEASURES`, then every free parameter."""
    by_name = {o.name: o for o in outcomes}
    varied = varied_settings(jobs)
    params: dict[str, None] = {}
    for o in outcomes:
        params.update(dict.fromkeys(o.row.get("parameters", {})))
    measured: dict[str, None] = dict.fromkeys(c for c, _ in MEASURES)
    for o in outcomes:
        measured.update(dict.fromkeys(k for k in o.row if k not in NOT_MEASURES))
    columns = ["name", "status", "seed", "generations", *varied, *measured]
    columns += [*params, "message"]
    rows = []
    for job in jobs:
        o = by_name.get(job.name)
        found = o.row if o is not None else {}
        status = found.get("status", "not run")
        if o is not None and o.status in ("error", "lost"):
            status = o.status
        values = {
            "name": job.name,
            "status": status,
            "seed": job.settings.seed,
            "generations": found.get("generations"),
            **{k: _setting(job, k) for k in varied},
            **{c: found.get(c) for c in measured},
            **found.get("parameters", {}),
            "message": o.message if o is not None else "",
        }
        rows.append([values.get(c) for c in columns])
    return columns, rows


def _setting(job: Job, key: str):
    value = job.settings.model_dump(mode="json")[key]
    return ",".join(str(v) for v in value) if isinstance(value, list) else value


def csv_text(columns: list[str], rows: list[list]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for r in rows:
        writer.writerow(["" if v is None else (repr(v) if isinstance(v, float) else v) for v in r])
    return buf.getvalue()


def html_text(columns: list[str], rows: list[list], title: str) -> str:
    """One page: the table of :func:`table`, through the report's renderer."""
    headings = dict(MEASURES)
    quiet = all(not r[columns.index("message")] for r in rows)
    shown = [c for c in columns if c != "frames_within_censored" and not (quiet and c == "message")]
    out_rows = []
    for r in rows:
        values = dict(zip(columns, r, strict=True))
        median = values[FRAMES_WITHIN]
        if median is not None:
            values[FRAMES_WITHIN] = censored_text(median, bool(values["frames_within_censored"]))
        out_rows.append([_cell(values[c], c) for c in shown])
    done = sum(1 for r in rows if r[1] == "completed")
    section = Section(
        "Fits",
        text=[
            f"{len(rows)} fits, {done} completed. RMS error: the fit's own cost as an RMS "
            "position error. Zero force: the constant-velocity predictor on the same one-step "
            "terms. Free-run RMS and frames within "
            f"{THRESHOLD_MM:g} mm: as in each run's report (first fitted recording; '>=' when "
            "the free runs reached the window's end first). Verdicts (fitted_..., and held_out_... "
            "after --validate): one step and 10 frames ahead, better than zero force by the "
            "gain (%) or not (red), with the markers where the model is not better. Then the "
            "identified parameters."
        ],
        tables=[Table([headings.get(c, c) for c in shown], out_rows)],
        anchor="fits",
    )
    return render(title, [section])


def _cell(value, column: str = ""):
    if isinstance(value, float) and math.isnan(value):
        return None
    if column.endswith("_verdict") and value in ("worse", "no better"):
        return Marked(value, f"{value} than zero force: {EXPLAINS_NOT}")
    return value


def write_summary(
    out: str | Path, jobs: Sequence[Job], outcomes: Sequence[Outcome], title: str
) -> tuple[Path, Path]:
    """OUT/summary.csv and OUT/summary.html, each written atomically."""
    out = Path(out)
    columns, rows = table(jobs, outcomes)
    csv_path = write_text_atomic(out / "summary.csv", csv_text(columns, rows))
    html_path = write_text_atomic(out / "summary.html", html_text(columns, rows, title))
    return csv_path, html_path
