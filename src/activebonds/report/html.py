"""One self-contained HTML report: tables, figures as base64 PNG data URIs, and a canvas player
whose numbers are an inline JSON blob. No external resource of any kind (works offline).

:func:`write_report` reports one run; :func:`write_comparison_report` builds a report from
any sections (e.g. standard vs neural series over several seeds), reusing the same pieces.
"""

from __future__ import annotations

import base64
import html
import json
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from ..document import Figure, Marked, Section, Table
from ..errors import InputError
from ..identify import stages
from ..identify.judge.baselines import zero_force_predictions
from ..identify.stages import baselines
from ..model.names import NEAR_BOUND
from . import animation, gait_plots, plots
from .files import check_replaceable, staged_directory, write_html
from .predict import Prediction, default_frames, predict_run
from .runs import RunRecord, load_run
from .tables import (
    Beyond,
    beyond_scores,
    errors_table,
    fmt,
    free_run_table,
    neural_table,
    parameters_table,
    searched_model,
    summary_table,
    verdict_text,
)

PLAYER_IDS = ("canvas", "play", "frame", "frame-label", "mode", "zoom", "speed")


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
    heights = gait_plots.gait_heights(found, fig_dir / "gait_heights", first_frame=first)
    cycle = gait_plots.gait_cycle(found, fig_dir / "gait_cycle")
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
    # the frames beyond the fit scored as evaluate scores them (the summary's verdict): the
    # one-step (model, zero force) RMS in mm, or None
    beyond_one_step: tuple[float, float] | None = None


def stage_sections(record: RunRecord, pred: Prediction, beyond=None) -> list[Section]:
    """The sections of the post-fit stages that left a record, in the registry's order
    (``beyond``: the frames beyond the fit as the summary scores them, :class:`.tables.Beyond`)."""
    one = beyond.comparisons[0] if beyond is not None and beyond.comparisons else None
    view = ReportView(record, pred, None if one is None else (one.model_mm, one.zero_force_mm))
    return [
        section
        for stage in stages.stages()
        if stage.name in record.records
        for section in stage.sections(record.records[stage.name], view)
    ]


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
    if beyond is not None and beyond.burn_in is not None:
        curve = plots.burn_in_curve(beyond.burn_in, fig_dir / "burn_in")
        caption = (
            "The held-out frames' free runs after a burn-in: the state estimated from the "
            "recorded frames before each start with the parameters held, then the run "
            "(identify/judge/burn_in.py)."
        )
        burn_in_figures = [Figure(curve[0], caption)]
    else:
        burn_in_figures = []
    sections = [
        _summary_section(record, pred, beyond, burn_in_figures),
        *stage_sections(record, pred, beyond),
        Section(
            "Convergence",
            figures=[Figure(conv[0], "Best and population-median cost as RMS position error.")],
            anchor="convergence",
        ),
        _animation_section(record, pred, frame_at, traj[0], errors[0], media),
        _parameters_section(record, params[0], searched),
    ]
    gait = gait_section(record, pred, fig_dir)
    if gait is not None:  # after the animation
        at = next(i for i, sec in enumerate(sections) if sec.anchor == "animation") + 1
        sections.insert(at, gait)
    if pred.neural.any():
        sections.append(_neurons_section(pred, model, labels, fig_dir, frame_at))
    sections.append(
        Section(
            "Mutation variants",
            figures=[Figure(variants[0], "Success rate and share of each mutation variant.")],
            anchor="variants",
        )
    )
    return sections


def _summary_section(
    record: RunRecord, pred: Prediction, beyond: Beyond | None, figures=()
) -> Section:
    """The verdicts in words and the run's tables: at a glance, free runs, errors; the
    free runs after a burn-in beyond the fit (``figures``), where scored."""
    return Section(
        "Summary",
        text=verdict_text(record, pred, beyond),
        figures=list(figures),
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
    )


def _animation_section(
    record: RunRecord, pred: Prediction, frame_at: dict, traj: Path, errors: Path, media
) -> Section:
    """Recorded vs model: the player, the trajectories' and the one-step errors' figures
    (``traj``, ``errors``), the animation's video and files (``media``)."""
    first = frame_at["first_frame"]
    extra = []
    if not pred.extended:
        extra.append(
            "Only the fitted window is shown: the original recording is gone, has changed or "
            "holds no later frame, or no more frames were asked for."
        )
    if pred.diverged_at is not None:
        extra.append(f"The free run went non-finite at frame {first + pred.diverged_at}.")
    return Section(
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
        animation=animation.payload([(record.label, pred)], title="recorded vs model", **frame_at),
        figures=[
            Figure(
                traj,
                "Positions against the recording's frame number (time on top): recorded, "
                "one-step predictions, free run.",
            ),
            Figure(
                errors,
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
    )


def _parameters_section(record: RunRecord, figure: Path, searched) -> Section:
    """The identified parameters: their figure within the bounds ``searched`` and table."""
    return Section(
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
        figures=[Figure(figure, "Identified parameters within their bounds (search space).")],
        tables=[parameters_table(record, searched)],
        anchor="parameters",
    )


def _neurons_section(pred: Prediction, model, labels, fig_dir: Path, frame_at: dict) -> Section:
    """The neurons: their input weights, their activations along the free run, saturation."""
    heat = plots.weight_heatmap(model, fig_dir / "weights")
    act = plots.activations(pred, labels, fig_dir / "activations", **frame_at)
    return Section(
        "Neurons",
        figures=[
            Figure(heat[0], "Input weights of each neuron (length and rate of the other bonds)."),
            Figure(act[0], "Activations along the free run."),
        ],
        tables=[neural_table(pred, labels)],
        anchor="neurons",
    )
