"""One self-contained HTML report: tables, figures as base64 PNG data URIs, and a canvas player
whose numbers are an inline JSON blob. No external resource of any kind (works offline).

:func:`write_report` reports one run; :func:`write_comparison_report` builds a report from
any sections (e.g. standard vs neural series over several seeds), reusing the same pieces.
"""

from __future__ import annotations

import base64
import html
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from ..document import Figure, Marked, Section, Table
from ..errors import InputError
from ..identify import stages
from ..identify.judge.ahead import DEFAULT_AHEAD
from ..identify.judge.ahead import comparisons as ahead_comparisons
from ..identify.judge.baselines import zero_force_predictions
from ..identify.judge.metrics import FreeRunMetrics
from ..identify.judge.predictions import rms_mm
from ..identify.judge.verdict import Comparison, comparisons_from, free_run_advice, verdict
from ..identify.judge.verdict import lines as verdict_lines
from ..identify.stages import baselines, validation
from ..model.names import NEAR_BOUND, parameter_rows
from . import animation, plots
from .files import check_replaceable, staged_directory, write_html
from .predict import Prediction, default_frames, predict_run
from .runs import RunRecord, load_run

PLAYER_IDS = ("canvas", "play", "frame", "frame-label", "mode", "zoom", "speed")


_OPTIMIZERS = {"es": "the paper's evolution strategy (es)", "random": "random search (random)"}


def fmt(x: object, digits: int = 4) -> str:
    """Numbers to short text (NaN/None as an em dash); other values as str."""
    if x is None:
        return "—"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int | np.integer):
        return str(int(x))
    if isinstance(x, float | np.floating):
        if not math.isfinite(float(x)):
            return "—" if math.isnan(float(x)) else ("∞" if x > 0 else "−∞")
        return f"{float(x):.{digits}g}"
    return str(x)


def _asset(name: str) -> str:
    return (resources.files("activebonds.report") / "assets" / name).read_text(encoding="utf-8")


def _img(path: Path, alt: str) -> str:
    """An embedded image, or for an MP4 an embedded video (a data: URI either way)."""
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    if Path(path).suffix.lower() == ".mp4":
        return (
            f'<video controls loop muted preload="metadata" aria-label="{html.escape(alt)}" '
            f'src="data:video/mp4;base64,{data}"></video>'
        )
    mime = {".png": "image/png", ".gif": "image/gif", ".svg": "image/svg+xml"}.get(
        Path(path).suffix.lower(), "image/png"
    )
    return f'<img src="data:{mime};base64,{data}" alt="{html.escape(alt)}">'


def _table(t: Table) -> str:
    out = ['<table class="kv">' if t.key_value else "<table>"]
    if t.caption:
        out.append(f"<caption>{html.escape(t.caption)}</caption>")
    if not t.key_value:
        out.append("<tr>" + "".join(f"<th>{html.escape(str(c))}</th>" for c in t.columns) + "</tr>")
    for row in t.rows:
        cells = []
        for i, v in enumerate(row):
            marked = isinstance(v, Marked)
            title = f' title="{html.escape(v.why)}"' if marked and v.why else ""
            v = v.value if marked else v
            text = html.escape(fmt(v))
            if t.key_value:
                cells.append(f"<th>{text}</th>" if i == 0 else f"<td>{text}</td>")
            else:
                num = isinstance(v, int | float | np.integer | np.floating) and not isinstance(
                    v, bool
                )
                classes = " ".join(
                    c for c in ("num" if num else "", "worse" if marked else "") if c
                )
                attr = f' class="{classes}"' if classes else ""
                cells.append(f"<td{attr}{title}>{text}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _player(index: int, anim: dict) -> str:
    suffix = "" if index == 0 else f"-{index + 1}"
    ids = {k: f"{k}{suffix}" for k in PLAYER_IDS}
    title = html.escape(anim.get("title") or "")
    speeds = "".join(
        f'<option value="{v}"{" selected" if v == 12 else ""}>{v} frames/s</option>'
        for v in (3, 6, 12, 30, 60)
    )
    return f"""<div class="player" data-index="{index}">
<canvas id="{ids["canvas"]}" width="760" height="460" aria-label="{title or "animation"}"></canvas>
<div class="controls">
<button type="button" class="play" id="{ids["play"]}" aria-pressed="false">&#9654; play</button>
<input type="range" class="frame" id="{ids["frame"]}" min="0" max="0" value="0" step="1" aria-label="frame">
<span class="frame-label" id="{ids["frame-label"]}">frame 0</span>
<label>show <select class="mode" id="{ids["mode"]}">
<option value="both" selected>one-step + free run</option>
<option value="one">one-step only</option>
<option value="free">free run only</option></select></label>
<label>view <select class="zoom" id="{ids["zoom"]}"><option value="all" selected>all markers</option></select></label>
<label>speed <select class="speed" id="{ids["speed"]}">{speeds}</select></label>
</div></div>
<p class="note">Black: recorded markers and bonds (grey: their paths). Circles, solid bonds:
one-step predictions (each frame from the recorded state of the two frames before).
Squares, dashed bonds: free run from the first two frames. Projection on the
{html.escape(" / ".join(anim.get("axes", [])))} axes (the two of largest spread).</p>"""


def _json_blob(data: dict) -> str:
    text = json.dumps(data, allow_nan=False, separators=(",", ":"))
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def render(title: str, sections: Sequence[Section], *, subtitle: str = "") -> str:
    """The whole HTML document as one string (CSS, images, data and JS inline)."""
    animations: list[dict] = []
    body: list[str] = []
    nav = []
    for k, s in enumerate(sections):
        anchor = s.anchor or f"s{k + 1}"
        nav.append(f'<a href="#{html.escape(anchor)}">{html.escape(s.title)}</a>')
        body.append(f'<section id="{html.escape(anchor)}"><h2>{html.escape(s.title)}</h2>')
        body.extend(f"<p>{html.escape(p)}</p>" for p in s.text)
        if s.animation is not None:
            body.append(_player(len(animations), s.animation))
            animations.append(s.animation)
        body.extend(_table(t) for t in s.tables)
        for f in s.figures:
            f = f if isinstance(f, Figure) else Figure(Path(f))
            cap = f"<figcaption>{html.escape(f.caption)}</figcaption>" if f.caption else ""
            body.append(f"<figure>{_img(f.path, f.caption or f.path.stem)}{cap}</figure>")
        body.extend(f'<p class="note">{html.escape(n)}</p>' for n in s.notes)
        body.append("</section>")
    script = ""
    if animations:
        script = (
            f'<script type="application/json" id="report-data">'
            f"{_json_blob({'animations': animations})}</script>\n<script>\n{_asset('player.js')}\n</script>"
        )
    sub = f'<p class="subtitle">{html.escape(subtitle)}</p>' if subtitle else ""
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{html.escape(title)}</title>
<link rel="icon" href="data:,">
<style>
{_asset("report.css")}
</style>
</head>
<body>
<h1>{html.escape(title)}</h1>
{sub}
<nav>{" ".join(nav)}</nav>
{chr(10).join(body)}
{script}
</body>
</html>
"""


def write_comparison_report(
    out_path: str | Path, title: str, sections: Sequence[Section], *, subtitle: str = ""
) -> Path:
    """Write a report made of ``sections`` to ``out_path`` atomically; returns the path.

    Figures are read (and embedded) now, so they may live in a folder that is about to be
    swapped in with :func:`activebonds.report.files.staged_directory`."""
    out_path = Path(out_path)
    return write_html(out_path, render(title, sections, subtitle=subtitle))


# ----------------------------------------------------------------------------- one run


def _markers_text(pred: Prediction) -> str:
    return ", ".join(
        n if n == m else f"{n} ← {m}" for n, m in zip(pred.names, pred.markers, strict=True)
    )


def summary_table(record: RunRecord, pred: Prediction) -> Table:
    """The run at a glance: inputs, settings, outcome, versions, wall time."""
    meta, st, s = record.meta, record.status, record.settings
    inputs = meta.get("inputs", {})
    w = record.window
    start = s.frames[0]
    gens_done = int(st.get("generation", len(record.history.get("generation", []))))
    per = ", ".join(
        f"{n} {fmt(v, 3)}" for n, v in zip(pred.names, pred.one_step_rms_mm, strict=True)
    )
    versions = ", ".join(f"{k} {v}" for k, v in sorted(meta.get("versions", {}).items()))
    be = meta.get("backend", {})
    wall = st.get("wall_seconds")
    rows = [
        ("run", str(record.path)),
        ("status", st.get("status", "unknown") + ("" if record.has_best else " (no best model)")),
        ("model", f"{record.model.name} ({inputs.get('model', {}).get('path', 'in memory')})"),
        ("bond variant", s.bonds),
        ("mass scale fixed by", record.model.spec.mass_scale()),
        ("data", inputs.get("data", {}).get("path", w.source or "in memory")),
        ("markers (particle ← marker)", _markers_text(pred)),
        (
            "frames fitted",
            f"{start}:{start + w.n_frames} ({w.n_frames} frames, {w.duration:.4g} s)",
        ),
        ("rate", f"{w.rate:g} Hz"),
        ("optimizer", _OPTIMIZERS.get(s.optimizer, s.optimizer)),
        ("population", s.population),
        ("generations", f"{gens_done} of {s.generations}"),
        ("seed", s.seed),
        (
            "cost",
            f"horizon {s.es_horizon}, {s.es_integrator} with {s.es_substeps} substep(s), {s.precision}",
        ),
        ("refinement", _refinement_text(s)),
        ("best RMS error (fit cost)", f"{fmt(st.get('best_rms_mm'))} mm"),
        ("best RMS per particle (one-step)", f"{per} mm"),
        ("failed evaluations", st.get("failed_evaluations", "—")),
        (
            "wall time (the run's, every session)",
            "—" if wall is None else f"{float(wall):.4g} s",
        ),
        ("versions", versions),
        ("backend", f"{be.get('backend', '?')} ({be.get('platform', '?')}), x64 {be.get('x64')}"),
        ("created", meta.get("created", "—")),
        ("command", meta.get("command", "—")),
    ]
    return Table(columns=("", ""), rows=rows, key_value=True, caption="Run")


def _refinement_text(s) -> str:
    if s.refine == "none":
        return "none"
    horizons = ", ".join(str(h) for h in s.horizon)
    return f"Levenberg-Marquardt (optimistix), {s.cost} cost, horizons {horizons}"


WORSE = "not better than zero force"


def _judged(model_mm: float, zero_mm: float):
    """The model's number, marked (red) where it does not beat zero force."""
    v = verdict(model_mm, zero_mm)
    return Marked(float(model_mm), v.text()) if v.better is False else model_mm


def zero_force_one_step_mm(pred: Prediction) -> tuple[np.ndarray, np.ndarray | None]:
    """The zero-force predictor's one-step RMS (mm) per particle on the terms of the model's
    (:attr:`Prediction.one_step_rms_mm`), over the fitted frames and beyond them."""
    one, _ = zero_force_predictions(pred.recorded, 1)
    fit, n = pred.fit_frames, pred.n_frames
    beyond = rms_mm(one, pred.recorded, slice(fit, n)) if n > fit else None
    return rms_mm(one, pred.recorded, slice(0, fit)), beyond


def errors_table(
    pred: Prediction,
    caption: str = "RMS position error per particle (mm)",
    beyond: Beyond | None = None,
) -> Table:
    """Per particle, the model's one-step and free-run RMS beside zero force's one-step RMS,
    on the fitted frames and beyond them; red where the model is not better. With ``beyond``
    (the frames beyond scored as ``evaluate`` scores them), its one step and K frames ahead
    beyond the fit, each beside zero force's."""
    zero_fit, zero_beyond = zero_force_one_step_mm(pred)
    cols = ["particle", "marker", "one-step (fit)", "zero force (fit)", "free run (fit)"]
    scored = beyond.comparisons if beyond is not None and pred.extended else ()
    if pred.extended:
        cols += ["one-step (beyond)", "zero force (beyond)", "free run (beyond)"]
    for c in scored[1:]:
        cols += [f"{c.horizon} ahead (beyond)", f"zero force {c.horizon} ahead (beyond)"]
    rows = []
    for p, (n, m) in enumerate(zip(pred.names, pred.markers, strict=True)):
        one = float(pred.one_step_rms_mm[p])
        row = [n, m, _judged(one, zero_fit[p]), float(zero_fit[p]), float(pred.free_run_rms_mm[p])]
        if pred.extended:
            one, zero = float(pred.one_step_rms_mm_beyond[p]), float(zero_beyond[p])
            if scored:  # evaluate's terms, as the verdict beyond
                one, zero = scored[0].model_per_marker[p], scored[0].zero_force_per_marker[p]
            row += [_judged(one, zero), zero, float(pred.free_run_rms_mm_beyond[p])]
        for c in scored[1:]:
            row += [
                _judged(c.model_per_marker[p], c.zero_force_per_marker[p]),
                c.zero_force_per_marker[p],
            ]
        rows.append(row)
    caption += f"; red: {WORSE} (the constant-velocity predictor, same terms)"
    if pred.extended:
        caption += (
            "; beyond: the frames after the fitted ones as a window of their own, as "
            "evaluate --frames scores them (the free run from their first two frames"
            + (
                ", the one-step and K-ahead predictions from their third frame on)"
                if scored
                else ")"
            )
        )
    return Table(columns=cols, rows=rows, caption=caption)


@dataclass(frozen=True)
class Beyond:
    """The frames beyond the fit scored as ``evaluate --frames START:STOP --horizon K`` scores
    them (:func:`~activebonds.identify.judge.ahead.comparisons`): their frames [start, stop) of the
    recording and the comparisons, one step then K frames ahead, overall and per marker."""

    frames: tuple[int, int]
    comparisons: tuple[Comparison, ...]

    @classmethod
    def from_record(cls, record: dict) -> Beyond:
        """From an evaluation's record (:meth:`.evaluate.Evaluation.record`, as ``auto``'s
        evaluation.json keeps its held-out one)."""
        a, b = record["frames"]
        return cls((int(a), int(b)), tuple(comparisons_from(record["comparisons"])))

    def lines(self) -> list[str]:
        a, b = self.frames
        return verdict_lines(f"frames beyond the fit {a}:{b}", self.comparisons)


def beyond_scores(record: RunRecord, pred: Prediction, horizon: int = DEFAULT_AHEAD) -> Beyond:
    """The frames the report predicts beyond the fitted window, scored by ``evaluate``'s code
    as ``evaluate RUN/best_model.toml DATA --frames START:STOP --horizon HORIZON`` scores them:
    a window of their own (the first prediction from their first two frames; the model's time
    starting at their first frame), the run's substeps and integrator."""
    from ..data import Trajectory

    s, fit = record.settings, pred.fit_frames
    rec = pred.recorded[fit:]
    window = Trajectory(rec, np.isfinite(rec).all(axis=-1), pred.markers, 1.0 / pred.dt)
    found = ahead_comparisons(
        record.model, window, horizon, substeps=s.substeps, method=s.integrator
    )
    start = int(s.frames[0])
    return Beyond((start + fit, start + pred.n_frames), tuple(found))


def verdict_text(record: RunRecord, pred: Prediction, beyond: Beyond | None = None) -> list[str]:
    """The verdicts in words (:mod:`activebonds.identify.judge.verdict`): on the fitted frames and,
    after ``fit --validate``, the validation frames (one step and K frames ahead, overall and
    per marker, as ``fit`` printed them), and on the frames beyond the fitted window
    (``beyond``: one step and K frames ahead, as ``evaluate`` scores them)."""
    out = []
    fitted = record.records.get(baselines.NAME, {})
    out += verdict_lines("fitted frames", comparisons_from(fitted.get("judged")))
    if "fitted" in fitted:
        run = FreeRunMetrics.from_dict(fitted["fitted"]["model"]).free_run_rms_mm
        out += [a for a in (free_run_advice(run, fitted.get("holds")),) if a is not None]
    held = record.records.get(validation.NAME)
    if held is not None and "judged" in held:
        a, b = held["frames"]
        out += verdict_lines(f"validation frames {a}:{b}", comparisons_from(held["judged"]))
    if beyond is not None:
        out += beyond.lines()
    return out


def free_run_table(record: RunRecord) -> Table | None:
    """One-step RMS, free-run RMS and frames within the threshold
    (:func:`activebonds.identify.judge.metrics.free_run_metrics`) of the model and the zero-force
    predictor on the fitted frames and, after ``fit --validate``, on the validation frames,
    as the baselines and validation stages recorded them."""
    s = record.settings
    start = s.frames[0]
    fitted = record.records.get(baselines.NAME, {}).get("fitted")
    if fitted is None:
        return None
    rows = baselines.free_run_rows(f"fitted {start}:{start + record.window.n_frames}", fitted)
    held = record.records.get(validation.NAME)
    if held is not None:
        frames = held["frames"]
        rows += baselines.free_run_rows(f"validation {frames[0]}:{frames[1]}", held)
    threshold = FreeRunMetrics.from_dict(fitted["model"]).threshold_mm
    return Table(
        (
            "",
            "frames",
            "one-step RMS (mm)",
            "free-run RMS (mm)",
            f"frames within {threshold:g} mm (median)",
            "starts",
        ),
        rows,
        "Free run. Free-run RMS: one run from the window's first two frames. Frames within "
        f"{threshold:g} mm: free runs from several start frames (spread over the window's "
        "first half), each counted until its worst marker is first off by more than "
        f"{threshold:g} mm; the median over starts, '>=' when runs reached the window's end "
        "first (censored). Zero force: constant velocity from the two start frames.",
    )


def gait_section(record: RunRecord, pred: Prediction, fig_dir: Path) -> Section | None:
    """The gait of the model's free runs (:mod:`activebonds.report.gait_runs`), when the
    model puts particles in contact with a surface (its feet) or has a rhythmic drive (its
    feet the lowest markers, up against its gravity or the recording's guess), and the feet's
    recorded heights have a period: on the frames after the fitted window when they hold two
    strides, else on the fitted window; None otherwise."""
    from ..data import Trajectory
    from . import gait as g
    from .gait_runs import COLUMNS, choose_feet, choose_up, contact_feet, gait_evaluation

    model = record.model
    if not contact_feet(model) and model.spec.drive is None:
        return None
    s = record.settings
    whole = pred.recorded
    whole_data = Trajectory(whole, np.isfinite(whole).all(axis=-1), pred.markers, 1.0 / pred.dt)
    try:
        up = choose_up(model, whole_data, None)[0]
        feet = choose_feet(model, whole_data, up, None)[0]
    except InputError:
        return None
    lo = 0
    if pred.extended:
        later = pred.recorded[pred.fit_frames :]
        t = g.dominant_period(g.vertical(later, up)[:, list(feet)])
        if np.isfinite(t) and later.shape[0] >= 2 * t:
            lo = pred.fit_frames
    window = pred.recorded[lo:]
    data = Trajectory(window, np.isfinite(window).all(axis=-1), pred.markers, 1.0 / pred.dt)
    first = int(s.frames[0]) + lo
    try:
        found = gait_evaluation(
            model, data, substeps=s.substeps, integrator=s.integrator, offset=lo, first_frame=first
        )
    except InputError:
        return None
    heights = plots.gait_heights(found, fig_dir / "gait_heights", first_frame=first)
    cycle = plots.gait_cycle(found, fig_dir / "gait_cycle")
    rows = [
        [Marked(c, "misses the target") if c == "FAIL" else c for c in row] for row in found.rows()
    ]
    which = "frames after the fitted window" if lo else "the fitted window"
    return Section(
        "Gait",
        text=[
            f"The free runs judged as a gait on {which} ({first}–{first + len(window) - 1}), "
            "whatever their phase: a run that drifts out of step with the recording loses "
            "nothing here, one that loses the rhythm, the feet's lift, the body's place or the "
            "stride's shape does. Each number beside the zero-force predictor's (constant "
            "velocity from the same frames) and its target."
        ],
        tables=[Table(COLUMNS, rows, found.caption)],
        figures=[
            Figure(heights[0], "Feet heights: the recording and the model's free runs."),
            Figure(cycle[0], "One stride: the recording's mean gait and the runs' averages."),
        ],
        anchor="gait",
    )


@dataclass(frozen=True)
class ReportView:
    """What a post-fit stage's report section may use: the run and the report's predictions."""

    run: RunRecord
    prediction: Prediction


def stage_sections(record: RunRecord, pred: Prediction) -> list[Section]:
    """The sections of the post-fit stages that left a record, in the registry's order."""
    view = ReportView(record, pred)
    return [
        section
        for stage in stages.stages()
        if stage.name in record.records
        for section in stage.sections(record.records[stage.name], view)
    ]


def searched_model(record: RunRecord):
    """The model whose bounds the fit searched: the run's input model (a best model written
    without min/max derives new bounds around its values); the best model if it is gone."""
    from ..identify.problem import variant
    from ..identify.rundir import RunDir

    try:
        return variant(RunDir(record.path).input_model(), record.settings.bonds)
    except (InputError, ValueError):
        return None


def parameters_table(record: RunRecord, searched=None) -> Table:
    """Each free parameter by its readable name, its value, search bounds, and "near min" or
    "near max" within 1 % of a bound (names.NEAR_BOUND); the machine key last."""
    rows = [
        (r.name, r.value, r.lower, r.upper, r.log, r.bound_text(), r.key)
        for r in parameter_rows(record.model, bounds=searched)
    ]
    columns = ("parameter", "value", "min", "max", "log search", "at a bound", "key")
    return Table(columns, rows, "Identified parameters")


def neural_table(pred: Prediction, labels: Sequence[str]) -> Table:
    rows = [("saturated samples (|a| > 0.95) along the free run", pred.saturated_share)]
    for b in np.flatnonzero(pred.neural):
        rows.append((f"  neuron {labels[b]}", float(pred.saturated_per_neuron[b])))
    rows.append(("near-zero weights (|w| < 1 % of the weight range)", pred.near_zero_weight_share))
    return Table(("", ""), rows, "Neurons", key_value=True)


def _report_paths(run: Path, out: str | Path | None) -> tuple[Path, Path]:
    if out is None:
        return run / "report.html", run / "figures"
    out = Path(out)
    if out.is_dir():
        out = out / "report.html"
    if out.suffix.lower() not in (".html", ".htm"):
        raise InputError(out, "the report file must end in .html")
    return out, out.with_name(f"{out.stem}-figures")


def write_report(
    run_dir: str | Path,
    out: str | Path | None = None,
    *,
    frames: int | None = None,
    status=None,
    beyond: Beyond | None = None,
    made: Sequence[str] = (),
) -> Path:
    """Write the report of one run: ``RUN/report.html`` (or ``out``) and its figures
    (``RUN/figures/*.png|svg``, ``animation.gif`` and, with ffmpeg, ``animation.mp4``;
    beside ``out``: ``STEM-figures/``).

    ``frames``: how many frames of the original recording to predict, from the fitted
    window's start (default: twice the window; only the window if the recording is gone or
    changed). ``status``: called with a line saying what is being done, once the run and the
    output are checked (the command line shows it). ``beyond``: the frames beyond the fit
    already scored (``auto``'s held-out evaluation, so that its report says what its
    terminal said); by default they are scored here as ``evaluate --horizon 10`` scores them.
    ``made``: lines saying how the model was made (``auto``'s steps), a section of their own.
    Raises :class:`InputError` for a missing
    or invalid run."""
    run = Path(run_dir)
    record = load_run(run)
    if frames is not None and frames < 1:
        raise InputError("--n-frames", "must be at least 1")
    html_path, fig_dir = _report_paths(run, out)
    if not html_path.absolute().parent.is_dir():
        raise InputError(html_path, "the folder does not exist")
    check_replaceable(fig_dir)
    if status is not None:
        status("writing the report (predictions, figures, animation)")
    pred, _ = predict_run(record, frames if frames is not None else default_frames(record))
    with staged_directory(fig_dir) as tmp:
        sections = run_sections(record, pred, tmp, beyond)
        if made:
            sections.insert(1, Section("How this model was made", text=list(made), anchor="made"))
        title = f"activebonds report: {run.resolve().name}"
        subtitle = f"{record.model.name}, {record.settings.bonds} bonds — {record.status.get('status', 'unknown')}"
        write_comparison_report(html_path, title, sections, subtitle=subtitle)
    return html_path


def run_sections(
    record: RunRecord, pred: Prediction, fig_dir: Path, beyond: Beyond | None = None
) -> list[Section]:
    """The sections of a one-run report; figures are written into ``fig_dir``. Frames are
    numbered as in the recording (the fitted window's first frame is the run's ``--frames``
    start). ``beyond``: the frames beyond the fit already scored (``auto``'s held-out
    evaluation); else, when the report predicts beyond the fit, they are scored here
    (:func:`beyond_scores`)."""
    model = record.model
    if beyond is None and pred.extended:
        beyond = beyond_scores(record, pred)
    first = int(record.settings.frames[0])
    frame_at = {"first_frame": first, "start_time": float(record.window.start_time)}
    labels = plots.bond_labels(model)
    refs = baselines.references(record.records.get(baselines.NAME, {"zero_force_rms_mm": None}))
    refs = [(name, value) for name, value in refs if value is not None]
    conv = plots.convergence(
        [plots.Series(record.label, [record.history])], fig_dir / "convergence", references=refs
    )
    traj = plots.trajectories(pred, fig_dir / "trajectories", **frame_at)
    zero_one, _ = zero_force_predictions(pred.recorded, 1)
    errors = plots.one_step_errors(pred, zero_one, fig_dir / "one_step_errors", **frame_at)
    searched = searched_model(record)
    params = plots.parameters(model, fig_dir / "parameters", bounds=searched)
    variants = plots.variant_success(record.history, fig_dir / "variants")
    media = animation.write_animation([(record.label, pred)], fig_dir / "animation.gif", **frame_at)
    extra = []
    if not pred.extended:
        extra.append(
            "Only the fitted window is shown: the original recording is gone, has changed or "
            "holds no later frame, or no more frames were asked for."
        )
    if pred.diverged_at is not None:
        extra.append(f"The free run went non-finite at frame {first + pred.diverged_at}.")
    sections = [
        Section(
            "Summary",
            text=verdict_text(record, pred, beyond),
            tables=[
                t
                for t in (
                    summary_table(record, pred),
                    free_run_table(record),
                    errors_table(pred, beyond=beyond),
                )
                if t is not None
            ],
            anchor="summary",
        ),
        *stage_sections(record, pred),
        Section(
            "Convergence",
            figures=[Figure(conv[0], "Best and population-median cost as RMS position error.")],
            anchor="convergence",
        ),
        Section(
            "Recorded vs model",
            text=[
                f"Frames {first}–{first + pred.fit_frames - 1} of the recording were fitted"
                + (
                    f"; frames {first + pred.fit_frames}–{first + pred.n_frames - 1} test "
                    "generalisation."
                    if pred.extended
                    else "."
                )
            ],
            animation=animation.payload(
                [(record.label, pred)], title="recorded vs model", **frame_at
            ),
            figures=[
                Figure(
                    traj[0],
                    "Positions against the recording's frame number (time on top): recorded, "
                    "one-step predictions, free run.",
                ),
                Figure(
                    errors[0],
                    "Each frame's one-step error (RMS over the markers), the model's beside "
                    "zero force's, on a log scale; red where the model is worse. Where it "
                    "rises far above the markers' noise in some frames only, the model misses "
                    "forces there (a contact, an impact).",
                ),
                *(
                    [Figure(media.mp4, f"The animation as a video ({media.mp4.name}).")]
                    if media.mp4
                    else []
                ),
            ],
            notes=[
                *extra,
                f"The same animation is saved as {media.gif.name}"
                + (f" and {media.mp4.name}" if media.mp4 else "")
                + " in the figures folder.",
                *([media.note] if media.note else []),
            ],
            anchor="animation",
        ),
        Section(
            "Parameters",
            text=[
                "Each parameter is named by its bond's kind and particles (or its type); the "
                "key column is its name in uncertainty.csv and the run's files. 'near min' or "
                f"'near max': the value is within {NEAR_BOUND * 100:g} % of the search range from "
                "that bound (of the log range for a log-searched parameter), where the "
                "search stopped rather than where the data put it: widen the bound and fit "
                "again. Free masses under total_mass are never flagged (their weights' "
                "common scale changes nothing)."
            ],
            figures=[
                Figure(params[0], "Identified parameters within their bounds (search space).")
            ],
            tables=[parameters_table(record, searched)],
            anchor="parameters",
        ),
    ]
    gait = gait_section(record, pred, fig_dir)
    if gait is not None:  # after the animation
        at = next(i for i, sec in enumerate(sections) if sec.anchor == "animation") + 1
        sections.insert(at, gait)
    if pred.neural.any():
        heat = plots.weight_heatmap(model, fig_dir / "weights")
        act = plots.activations(pred, labels, fig_dir / "activations", **frame_at)
        sections.append(
            Section(
                "Neurons",
                figures=[
                    Figure(
                        heat[0],
                        "Input weights of each neuron (length and rate of the other bonds).",
                    ),
                    Figure(act[0], "Activations along the free run."),
                ],
                tables=[neural_table(pred, labels)],
                anchor="neurons",
            )
        )
    sections.append(
        Section(
            "Mutation variants",
            figures=[Figure(variants[0], "Success rate and share of each mutation variant.")],
            anchor="variants",
        )
    )
    return sections
