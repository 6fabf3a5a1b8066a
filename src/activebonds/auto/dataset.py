"""``activebonds auto`` over a dataset: every trial ``auto``'d into a folder of its own
(``OUT/<trial>``), in parallel as Ray tasks (this machine, or a cluster), or one after
another; then ``OUT/summary.csv`` and ``OUT/index.html``, a row a trial.

A trial is :func:`activebonds.auto.run` on one recording, so rerunning the same command keeps
each trial's finished steps and resumes an interrupted fit from its checkpoint (a Ray task
whose worker died is retried the same way). A trial that cannot be read or modelled is one
row saying why; the others go on. A row is read back from the trial's folder (``auto.json``,
``evaluation.json``), so a finished trial's row is the same whether it ran now or before.
"""

from __future__ import annotations

import csv
import glob
import html
import io
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from .folder import Options

SUFFIXES = (".c3d", ".trc", ".csv", ".npz", ".mat")
COLUMNS = (
    "trial", "recording", "status", "family", "held_out_frames",
    "one_step_mm", "zero_force_one_step_mm", "one_step_verdict",
    "ahead", "ahead_mm", "zero_force_ahead_mm", "ahead_verdict",
    "markers_worse_one_step", "markers", "wall_s", "report", "message",
)  # fmt: skip


@dataclass(frozen=True)
class Trial:
    name: str  # its folder under OUT
    path: Path


def trials(inputs: list[str | Path]) -> list[Trial]:
    """The recordings named by ``inputs`` (files, folders: the recordings in them, globs), in
    order, each once, with a folder name each (the file's stem; ``-2``, ``-3`` after it where
    two stems are the same). InputError where an input names nothing."""
    paths: list[Path] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            found = sorted(q for q in p.iterdir() if q.suffix.lower() in SUFFIXES)
        elif p.exists():
            found = [p]
        else:
            found = [Path(q) for q in sorted(glob.glob(str(item)))]
        if not found:
            raise InputError(str(item), "names no recording (a file, a folder of them, a glob)")
        paths += [q for q in found if q.absolute() not in {r.absolute() for r in paths}]
    out, used = [], set()
    for p in paths:
        name, k = p.stem, 1
        while name in used:
            k += 1
            name = f"{p.stem}-{k}"
        used.add(name)
        out.append(Trial(name, p))
    return out


def run_trial(trial: Trial, out: Path, options: Options) -> dict:
    """One trial ``auto``'d into ``out/<name>`` (quietly: its lines in ``auto.log`` there);
    its summary row. Errors become the row's message; Ctrl-C is raised."""
    from . import run

    folder = out / trial.name
    start = time.perf_counter()
    lines: list[str] = []
    status, message = "done", ""
    from ..sweep.run import mark_running

    mark = mark_running(out, trial.name)
    try:
        run(trial.path, folder, options, say=lines.append, verbose=False)
    except InputError as e:
        status, message = "error", e.line()
    except Exception as e:  # noqa: BLE001 - one trial's failure does not stop the others
        status, message = "error", f"{type(e).__name__}: {e}"
    finally:
        mark.unlink(missing_ok=True)
        if folder.is_dir():
            with open(folder / "auto.log", "a", encoding="utf-8") as log:
                log.writelines(f"{line}\n" for line in lines)
    return row(trial, folder, status, " ".join(message.split()), time.perf_counter() - start)


def row(trial: Trial, folder: Path, status: str, message: str, wall: float) -> dict:
    """The summary's row of a trial, read from its folder."""
    out = dict.fromkeys(COLUMNS, "")
    out.update(trial=trial.name, recording=str(trial.path), status=status, message=message)
    out["wall_s"] = round(wall, 1)
    try:
        state = json.loads((folder / "auto.json").read_text(encoding="utf-8"))
        held = json.loads((folder / "evaluation.json").read_text(encoding="utf-8"))["held_out"]
    except (OSError, ValueError, KeyError):
        return out
    fit = state.get("steps", {}).get("fit") or {}
    kept = [
        c.get("candidate", "") for c in fit.get("candidates", []) if c.get("run") == fit.get("run")
    ]
    out["family"] = kept[0] if kept else fit.get("run", "")
    out["held_out_frames"] = "{}:{}".format(*held["frames"])
    comps = held.get("comparisons", [])
    for comp, prefix in zip(comps[:2], ("one_step", "ahead"), strict=False):
        verdict = comp.get("verdict") or {}
        out[f"{prefix}_mm"] = _num(comp.get("model_mm"))
        out[f"zero_force_{prefix}_mm"] = _num(comp.get("zero_force_mm"))
        out[f"{prefix}_verdict"] = verdict.get("verdict", "")
        if prefix == "ahead":
            out["ahead"] = comp.get("horizon", "")
    if comps:
        out["markers_worse_one_step"] = len(comps[0].get("worse_markers") or [])
        out["markers"] = len(comps[0].get("markers") or [])
    if (folder / "report.html").is_file():
        out["report"] = f"{trial.name}/report.html"
    if status == "done":  # the trial's own time, whether it ran now or before
        out["wall_s"] = round(float(state.get("total_seconds", wall)), 1)
    return out


def _num(x) -> float | str:
    """Four significant digits (an exact model's error is small, not 0)."""
    return "" if x is None else float(f"{float(x):.4g}")


# ----------------------------------------------------------------------------- running


def run_dataset(
    items: list[Trial], out: Path, options: Options, ray: bool, done: Callable[[dict], None]
) -> list[dict]:
    """Every trial, as a Ray task of one CPU on the cluster this process is connected to
    (``ray``), else one after another; ``done`` hears of each row as it ends. The summary and
    index are written after each trial, so an interrupted dataset keeps the rows it has."""
    out.mkdir(parents=True, exist_ok=True)
    rows: dict[str, dict] = {}

    def finished(r: dict) -> None:
        rows[r["trial"]] = r
        write_summary(out, [rows[t.name] for t in items if t.name in rows])
        done(r)

    from ..sweep.run import tidy

    try:
        if ray:
            _run_ray(items, out, options, finished)
        else:
            for trial in items:
                finished(run_trial(trial, out, options))
    finally:
        tidy(out)  # no mark left: no trial runs (a killed worker's mark stays)
    return [rows[t.name] for t in items]


def _ray_trial(trial: Trial, out: str, options: Options) -> dict:
    from ..runtime import compilation_cache, fast_cpu_flags

    fast_cpu_flags()
    compilation_cache()
    return run_trial(trial, Path(out), options)


def _run_ray(items: list[Trial], out: Path, options: Options, finished) -> None:
    from ..sweep.run import first_line, ray_each

    def lost(trial: Trial, err: Exception) -> dict:
        message = f"lost: {first_line(err)}; run the same command again to resume it"
        return row(trial, out / trial.name, "error", message, 0.0)

    ray_each(_ray_trial, items, (str(out.absolute()), options), finished, lost)


# ----------------------------------------------------------------------------- the summary


def write_summary(out: Path, rows: list[dict]) -> None:
    """``out/summary.csv`` and ``out/index.html``, each written whole (a temporary file
    renamed into place)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    _replace(out / "summary.csv", buf.getvalue())
    _replace(out / "index.html", index_html(rows))


def _replace(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def index_html(rows: list[dict]) -> str:
    """The dataset's page: a table, a row a trial, each score beside zero force's and the
    verdict, a link to the trial's report."""
    shown = ("trial", "status", "family", "held_out_frames", "one_step_mm",
             "zero_force_one_step_mm", "one_step_verdict", "ahead", "ahead_mm",
             "zero_force_ahead_mm", "ahead_verdict", "markers_worse_one_step", "markers",
             "wall_s", "message")  # fmt: skip
    head = "".join(f"<th>{html.escape(c.replace('_', ' '))}</th>" for c in shown)
    body = []
    for r in rows:
        cells = []
        for c in shown:
            text = html.escape(str(r.get(c, "")))
            if c == "trial" and r.get("report"):
                text = f'<a href="{html.escape(r["report"])}">{text}</a>'
            cells.append(f"<td>{text}</td>")
        body.append(f"<tr>{''.join(cells)}</tr>")
    better = sum(1 for r in rows if r.get("one_step_verdict") == "better")
    return (
        "<!doctype html><html><head><meta charset='utf-8'><title>activebonds auto: dataset"
        "</title><style>body{font-family:sans-serif}td,th{padding:2px 8px;border-bottom:1px "
        "solid #ddd;text-align:right}td:first-child{text-align:left}</style></head><body>"
        f"<h1>activebonds auto over {len(rows)} trial(s)</h1><p>Held-out frames of each "
        "trial (its last share, never fitted), the kept model beside the zero-force "
        f"(constant-velocity) predictor: one step better at {better} of {len(rows)}.</p>"
        f"<table><tr>{head}</tr>{''.join(body)}</table></body></html>\n"
    )
