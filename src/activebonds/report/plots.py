"""Report figures (matplotlib's object API, drawn by Agg; the backend is left alone): each function writes ``STEM.png`` and ``STEM.svg`` and
returns both paths, PNG first.

Colours: the recording is black, one-step predictions blue, the free run orange; series of a
comparison take the default colour cycle in order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import matplotlib.ticker as mticker
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import TwoSlopeNorm
from matplotlib.figure import Figure

from ..data.orientation import AXES
from ..identify.judge.predictions import neural_bonds, to_mm
from ..identify.search.operators import VARIANTS
from ..model import Model
from ..model.names import parameter_label, parameter_rows
from .plots_large import LABELLED, parameters_compact, shown_particles
from .predict import Prediction, neural_weights
from .runs import history_rms_mm

RECORDED = "black"
ONE_STEP = "tab:blue"
FREE_RUN = "tab:orange"
DPI = 110


@dataclass(frozen=True)
class Series:
    """One labelled series of runs (e.g. one bond variant over several seeds)."""

    label: str
    histories: Sequence[dict[str, np.ndarray]]  # history.csv columns of each run


def _subplots(*grid, figsize, layout=None, dpi=None, **kwargs):
    """A figure and its axes from matplotlib's object API, drawn by Agg, with no pyplot
    state and no change of the process's backend."""
    fig = Figure(figsize=figsize, layout=layout, dpi=dpi)
    FigureCanvasAgg(fig)
    return fig, fig.subplots(*grid, **kwargs)


def save(fig, stem: str | Path) -> list[Path]:
    """Write the figure as STEM.png and STEM.svg (no timestamps), return the paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    png, svg = stem.with_suffix(".png"), stem.with_suffix(".svg")
    with matplotlib.rc_context({"svg.hashsalt": "activebonds", "svg.fonttype": "none"}):
        fig.savefig(png, dpi=DPI, metadata={"Software": None})
        fig.savefig(svg, metadata={"Date": None})
    return [png, svg]


def _stack(curves: list[np.ndarray]) -> np.ndarray:
    n = max((len(c) for c in curves), default=0)
    out = np.full((len(curves), n), np.nan)
    for i, c in enumerate(curves):
        out[i, : len(c)] = c
    return out


def _nanpercentile(a: np.ndarray, q) -> np.ndarray:
    a = np.where(np.isfinite(a), a, np.nan)
    out = np.full((len(np.atleast_1d(q)), a.shape[1]), np.nan)
    cols = np.isfinite(a).any(axis=0)
    if cols.any():
        out[:, cols] = np.nanpercentile(a[:, cols], q, axis=0).reshape(len(out), -1)
    return out


def convergence(
    series: Sequence[Series],
    stem: str | Path,
    *,
    band: bool | None = None,
    title: str = "Convergence",
    references: Sequence[tuple[str, float | None]] = (),
) -> list[Path]:
    """Best (solid) and population-median (dashed) cost as RMS error (mm) per generation,
    log scale. With several runs in a series and ``band`` (default: when any series has more
    than one run), the lines are medians across runs and the best cost's interquartile range
    is shaded. ``references``: (label, RMS mm) drawn as horizontal lines (e.g. the zero-force
    baseline, an exact optimum, a floor) where they fall within 100x of the curves. The
    final best value of each series is written beside its last point, and labelled ticks
    (powers of ten) bracket it on the y axis."""
    fig = convergence_figure(series, band=band, title=title, references=references)
    return save(fig, stem)


def final_values(fig) -> list[float]:
    """The final best values that :func:`convergence_figure` marked (mm)."""
    return list(getattr(fig, "activebonds_final", []))


def _decade_ticks(lo: float, hi: float, finals: Sequence[float]) -> list[float]:
    """Major ticks of a log axis from ``lo`` to ``hi``: powers of ten (every decade up to 12
    of them, else a regular stride), always with the two that bracket each final value."""
    a, b = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
    stride = max(1, math.ceil((b - a + 1) / 12))
    exps = set(range(a - a % stride, b + 1, stride))
    for v in finals:
        e = math.log10(v)
        exps |= {math.floor(e), math.ceil(e)}
    return [10.0**e for e in sorted(exps)]


def convergence_figure(
    series: Sequence[Series],
    *,
    band: bool | None = None,
    title: str = "Convergence",
    references: Sequence[tuple[str, float | None]] = (),
):
    """The figure of :func:`convergence` (unsaved); its final best values are listed by
    :func:`final_values`."""
    fig, ax = _subplots(figsize=(7.5, 4.2), layout="constrained")
    finals: list[tuple[float, float, str] | None] = []  # (generation, value, colour)
    colors = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    if band is None:
        band = any(len(s.histories) > 1 for s in series)
    drawn = False
    for i, s in enumerate(series):
        drawn |= _series_lines(ax, s, colors[i % len(colors)], band, finals)
    if drawn:
        ax.set_yscale("log")
        _reference_lines(ax, references)
        fig.activebonds_final = _mark_finals(ax, [f for f in finals if f is not None])
        ax.legend(fontsize=8, loc="upper right")
    else:
        ax.text(
            0.5, 0.5, "no generation recorded", ha="center", va="center", transform=ax.transAxes
        )
    ax.set_xlabel("generation")
    ax.set_ylabel("RMS position error (mm)")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    return fig


def _series_lines(ax, s: Series, color, band: bool, finals: list) -> bool:
    """One series' best (solid) and population-median (dashed) lines in ``color``: medians
    across its runs with the best cost's interquartile range shaded where ``band`` and it has
    several, else each run's; the last point of each best line appended to ``finals``. False
    where it has no generation."""
    rms = [history_rms_mm(h) for h in s.histories]
    if not rms or all(len(r["best"]) == 0 for r in rms):
        return False
    best, median = _stack([r["best"] for r in rms]), _stack([r["median"] for r in rms])
    gens = np.arange(1, best.shape[1] + 1)
    n = len(rms)
    if band and n > 1:
        q = _nanpercentile(best, [25, 50, 75])
        ax.fill_between(gens, q[0], q[2], color=color, alpha=0.25, linewidth=0)
        ax.plot(gens, q[1], color=color, lw=1.8, label=f"{s.label}: best (median of {n}, IQR)")
        finals.append(_last(gens, q[1], color))
        ax.plot(
            gens,
            _nanpercentile(median, [50])[0],
            color=color,
            lw=1,
            ls="--",
            label=f"{s.label}: population median",
        )
    else:
        for k in range(n):
            lab = s.label if n == 1 else f"{s.label} #{k + 1}"
            ax.plot(gens, best[k], color=color, lw=1.6, label=f"{lab}: best")
            finals.append(_last(gens, best[k], color))
            ax.plot(gens, median[k], color=color, lw=1, ls="--", label=f"{lab}: population median")
    return True


def _reference_lines(ax, references: Sequence[tuple[str, float | None]]) -> None:
    """(label, RMS mm) as horizontal lines, those within 100x of the log axis' range."""
    lo, hi = ax.get_ylim()
    styles = [":", "-.", (0, (5, 2, 1, 2)), (0, (1, 3))]
    for k, (label, value) in enumerate(references):
        if value is None or not np.isfinite(value) or not lo / 100 <= value <= hi * 100:
            continue
        ax.axhline(
            value, color="0.35", lw=1.1, ls=styles[k % len(styles)],
            label=f"{label}: {value:.4g} mm",
        )  # fmt: skip


def _mark_finals(ax, marked: list[tuple[float, float, str]]) -> list[float]:
    """Each final best value (generation, value, colour) marked and written beside its point,
    the log axis' labelled ticks (powers of ten) bracketing them; returns the values."""
    values = [v for _, v, _ in marked]
    if values:  # the decades around each final value are in view (labelled ticks)
        lo, hi = ax.get_ylim()
        below = 10.0 ** math.floor(math.log10(min(values)))
        above = 10.0 ** math.ceil(math.log10(max(values)))
        ax.set_ylim(min(lo, below / 1.15), max(hi, above * 1.15))
    lo, hi = ax.get_ylim()
    ax.yaxis.set_major_locator(mticker.FixedLocator(_decade_ticks(lo, hi, values)))
    plain = mticker.FuncFormatter(lambda v, _: f"{v:g}")
    ax.yaxis.set_major_formatter(plain)
    ax.yaxis.set_minor_formatter(plain if hi / lo < 30 else mticker.NullFormatter())
    for gen, value, color in marked:
        ax.plot([gen], [value], "o", color=color, ms=4)
        ax.annotate(
            f"{value:.3g} mm",
            (gen, value),
            xytext=(-4, -9),
            textcoords="offset points",
            ha="right",
            va="top",
            fontsize=8,
            color=color,
            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8},
        )
    return values


def _last(gens: np.ndarray, values: np.ndarray, color) -> tuple[float, float, str] | None:
    """(generation, value, colour) of the last finite positive value, or None."""
    ok = np.flatnonzero(np.isfinite(values) & (values > 0))
    if ok.size == 0:
        return None
    return float(gens[ok[-1]]), float(values[ok[-1]]), color


def parameters(
    model: Model,
    stem: str | Path,
    *,
    title: str = "Identified parameters",
    bounds: Model | None = None,
) -> list[Path]:
    """One horizontal bar per gene (named as people read it): its bounds in search space
    mapped to [0, 1], a marker at the identified value (red within 1 % of a bound:
    :func:`activebonds.model.names.at_bound`), the value written beside it; log-searched genes
    are marked. ``bounds``: the model whose bounds were searched (default ``model``)."""
    rows = parameter_rows(model, bounds=bounds)
    n = len(rows)
    if n > LABELLED:
        return save(parameters_compact(rows, title), stem)
    fig, ax = _subplots(figsize=(7.5, max(1.6, 0.28 * n + 1.0)), layout="constrained")
    if n == 0:
        ax.text(0.5, 0.5, "no free parameter", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return save(fig, stem)
    pos = np.array([r.position for r in rows])
    pos = np.clip(np.nan_to_num(pos, nan=0.5), 0.0, 1.0)
    y = np.arange(n)[::-1]
    ax.barh(y, np.ones(n), color="0.9", edgecolor="0.6", height=0.6)
    edge = np.array([r.bound is not None for r in rows])
    ax.scatter(pos, y, color=np.where(edge, "tab:red", "tab:blue"), zorder=3, s=22)
    for yi, r in zip(y, rows, strict=True):
        ax.text(1.02, yi, f"{r.value:.4g}  [{r.lower:.3g}, {r.upper:.3g}]", va="center", fontsize=7)
    labels = [f"{r.name}{'  (log)' if r.log else ''}" for r in rows]
    ax.set_yticks(y, labels, fontsize=7)
    ax.set_xlim(0, 1.42)
    ax.set_xticks([0, 0.5, 1], ["min", "mid", "max"])
    ax.set_xlabel("position within the bounds (search space; log genes on a log scale)")
    ax.set_title(title + ("  (red: within 1 % of a bound)" if edge.any() else ""))
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)
    return save(fig, stem)


def gene_label(model: Model, name: str) -> str:
    """'bond[2].stiffness' -> 'spring mouth-foot stiffness' (names.parameter_label)."""
    return parameter_label(model.spec, name)


def bond_labels(model: Model) -> list[str]:
    """'A–B' for each of the report's per-bond rows (predict.neural_bonds)."""
    names = model.particle_names
    rows, _ = neural_bonds(model.topology)
    return ["–".join(names[i] for i in row) for row in rows]


def weight_heatmap(
    model: Model, stem: str | Path, *, title: str = "Neural input weights"
) -> list[Path]:
    """Rows: neurons (neural bonds); columns: the length then the rate weights of the other
    bonds. Diverging colours centred at 0; unused entries (a neuron's own bond) are blank."""
    w_len, w_rate, span = neural_weights(model)
    _, neural = neural_bonds(model.topology)
    labels = bond_labels(model)
    rows = np.flatnonzero(neural)
    m = np.concatenate([w_len, w_rate], axis=1)[rows] if rows.size else np.zeros((0, 0))
    fig, ax = _subplots(
        figsize=(max(4.5, 0.9 * m.shape[1] + 2.5), max(2.0, 0.55 * len(rows) + 1.6)),
        layout="constrained",
    )
    if rows.size == 0:
        ax.text(0.5, 0.5, "no neural bond", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return save(fig, stem)
    finite = np.isfinite(m)
    vmax = float(np.nanmax(np.abs(m))) if finite.any() else 1.0
    vmax = vmax if vmax > 0 else (float(np.nanmax(span)) / 2 if np.isfinite(span).any() else 1.0)
    cmap = matplotlib.colormaps["RdBu_r"].with_extremes(bad="0.85")
    im = ax.imshow(
        np.ma.masked_invalid(m), cmap=cmap, norm=TwoSlopeNorm(0.0, -vmax, vmax), aspect="auto"
    )
    for r in range(m.shape[0]):
        for c in range(m.shape[1]):
            if finite[r, c]:
                ax.text(
                    c,
                    r,
                    f"{m[r, c]:.2g}",
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="white" if abs(m[r, c]) > 0.6 * vmax else "black",
                )
    n_b = len(labels)
    cols = [f"L {b}" for b in labels] + [f"dL/dt {b}" for b in labels]
    ax.set_xticks(range(2 * n_b), cols, rotation=45, ha="right", fontsize=7)
    ax.set_yticks(range(len(rows)), [f"neuron {labels[r]}" for r in rows], fontsize=7)
    ax.axvline(n_b - 0.5, color="k", lw=1)
    fig.colorbar(im, ax=ax, label="weight")
    ax.set_title(title + "  (inputs: elongation L, rate dL/dt)", fontsize=10)
    return save(fig, stem)


def variant_success(
    history: dict[str, np.ndarray], stem: str | Path, *, title: str = "Mutation variants"
) -> list[Path]:
    """Share of the children of each mutation variant that beat their own parent (a crossover
    child: the best of its parents), per generation (moving sums over about 2 % of the run),
    and each variant's share of trials."""
    gens = np.asarray(history.get("generation", []), np.float64)
    fig, (ax, bx) = _subplots(2, 1, figsize=(7.5, 4.8), sharex=True, layout="constrained")
    present = all(f"trials_{v.name}" in history for v in VARIANTS)
    if gens.size == 0 or not present:
        text = "no generation recorded" if present else "this optimiser has no mutation variants"
        ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes)
        return save(fig, stem)
    win = max(1, len(gens) // 50)

    def smooth(a: np.ndarray) -> np.ndarray:
        return np.convolve(np.asarray(a, np.float64), np.ones(win), mode="same")

    trials = [np.asarray(history[f"trials_{v.name}"], np.float64) for v in VARIANTS]
    trials_all = smooth(sum(trials))
    for v in VARIANTS:
        t, s = smooth(history[f"trials_{v.name}"]), smooth(history[f"successes_{v.name}"])
        with np.errstate(invalid="ignore", divide="ignore"):
            ax.plot(gens, np.where(t > 0, s / t, np.nan), lw=1.2, label=v.label)
            bx.plot(gens, np.where(trials_all > 0, t / trials_all, np.nan), lw=1.2)
    ax.set_ylabel("success rate")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=7, ncol=2, loc="upper right")
    ax.set_title(title + (f"  (moving window of {win} generations)" if win > 1 else ""))
    bx.set_ylabel("share of children")
    bx.set_xlabel("generation")
    bx.set_ylim(0, 1)
    for a in (ax, bx):
        a.grid(True, alpha=0.3)
    return save(fig, stem)


def _limits(rec: np.ndarray) -> tuple[float, float]:
    lo, hi = float(np.nanmin(rec)), float(np.nanmax(rec))
    pad = max(0.25 * (hi - lo), 0.01)
    return lo - pad, hi + pad


def frame_numbers(pred: Prediction, first_frame: int = 0) -> np.ndarray:
    """The recording's numbers of the prediction's frames (its first is ``first_frame``)."""
    return int(first_frame) + np.arange(pred.n_frames)


def _time_axis(ax, pred: Prediction, first_frame: int, start_time: float, **label) -> None:
    """A secondary x axis on top: the recording's time (s) of the frame numbers below."""
    dt, t0 = float(pred.dt), float(start_time) - int(first_frame) * float(pred.dt)
    top = ax.secondary_xaxis("top", functions=(lambda f: t0 + f * dt, lambda t: (t - t0) / dt))
    top.set_xlabel("time in the recording (s)", **label)
    top.tick_params(labelsize=7)


def trajectories(
    pred: Prediction,
    stem: str | Path,
    *,
    title: str = "Recorded vs predicted",
    first_frame: int = 0,
    start_time: float = 0.0,
) -> list[Path]:
    """One panel per particle and axis (position in mm against the frame number in the
    recording, time on top): the recording, the one-step predictions and the free run; the end
    of the fitted window is a vertical line. The y range follows the recording, so a
    diverging free run leaves the panel. ``first_frame``/``start_time``: the recording's
    number and time (s) of the prediction's first frame."""
    fig = trajectories_figure(pred, title=title, first_frame=first_frame, start_time=start_time)
    return save(fig, stem)


def trajectories_figure(
    pred: Prediction,
    *,
    title: str = "Recorded vs predicted",
    first_frame: int = 0,
    start_time: float = 0.0,
):
    """The figure of :func:`trajectories` (unsaved)."""
    dim = pred.recorded.shape[2]
    shown = shown_particles(pred)
    n_p = len(shown)
    fig, axes = _subplots(
        n_p,
        dim,
        figsize=(3.0 * dim + 1, 1.9 * n_p + 0.9),
        sharex=True,
        squeeze=False,
        layout="constrained",
    )
    t = frame_numbers(pred, first_frame)
    for row, p in enumerate(shown):
        for d in range(dim):
            ax = axes[row, d]
            rec = to_mm(pred.recorded[:, p, d])
            ax.plot(t, rec, color=RECORDED, lw=1.5, label="recorded")
            ax.plot(
                t,
                to_mm(pred.one_step[:, p, d]),
                ls="none",
                marker="o",
                ms=3,
                color=ONE_STEP,
                label="one-step",
            )
            ax.plot(
                t, to_mm(pred.free_run[:, p, d]), color=FREE_RUN, lw=1.2, ls="--", label="free run"
            )
            if np.isfinite(rec).any():
                ax.set_ylim(*_limits(rec))
            if pred.extended:
                ax.axvline(t[pred.fit_frames - 1], color="0.5", lw=0.8, ls=":")
            ax.tick_params(labelsize=7)
            if row == 0:
                ax.set_title(f"{AXES[d]} (mm)", fontsize=9)
                _time_axis(ax, pred, first_frame, start_time, fontsize=7)
            if d == 0:
                ax.set_ylabel(pred.names[p], fontsize=9)
            if row == n_p - 1:
                ax.set_xlabel("frame (of the recording)", fontsize=8)
    axes[0, 0].legend(fontsize=7, loc="best")
    note = "  (dotted line: end of the fitted window)" if pred.extended else ""
    total = pred.recorded.shape[1]
    if n_p < total:
        note += f"\nthe {n_p} of {total} markers predicted worst one step on the fitted frames"
    fig.suptitle(title + note, fontsize=10)
    return fig


ZERO_FORCE = "0.55"  # grey: the zero-force predictor


def frame_errors_mm(predicted: np.ndarray, recorded: np.ndarray) -> np.ndarray:
    """The one-step error of each frame (mm): the RMS over the markers of the 3-D distance
    between ``predicted`` and ``recorded`` [F, P, D]; NaN where no marker is scored."""
    err2 = np.sum((np.asarray(predicted) - np.asarray(recorded)) ** 2, axis=-1)  # [F, P]
    seen = np.isfinite(err2)
    count = seen.sum(axis=1)
    total = np.where(seen, err2, 0.0).sum(axis=1)
    return np.where(count > 0, 1000.0 * np.sqrt(total / np.maximum(count, 1)), np.nan)


def one_step_errors(
    pred: Prediction,
    zero_force: np.ndarray,
    stem: str | Path,
    *,
    first_frame: int = 0,
    start_time: float = 0.0,
) -> list[Path]:
    """Each frame's one-step error, the model's beside the zero-force predictor's
    (``zero_force`` [F, P, D] its predictions), on a log scale: where the model's curve is
    above, it explains that part of the motion worse than doing nothing."""
    fig = one_step_errors_figure(pred, zero_force, first_frame=first_frame, start_time=start_time)
    return save(fig, stem)


def one_step_errors_figure(
    pred: Prediction, zero_force: np.ndarray, *, first_frame: int = 0, start_time: float = 0.0
):
    """The figure of :func:`one_step_errors` (unsaved)."""
    fig, ax = _subplots(figsize=(8.0, 2.8), layout="constrained")
    t = frame_numbers(pred, first_frame)
    model = frame_errors_mm(pred.one_step, pred.recorded)
    zero = frame_errors_mm(zero_force, pred.recorded)
    ax.plot(t, zero, color=ZERO_FORCE, lw=1.0, label="zero force")
    ax.plot(t, model, color=ONE_STEP, lw=1.2, label="model")
    worse = np.isfinite(model) & np.isfinite(zero) & (model > zero)
    ax.plot(
        t[worse],
        model[worse],
        ls="none",
        marker="o",
        ms=2.5,
        color="tab:red",
        label="model worse than zero force",
    )
    if np.isfinite(model).any() and np.nanmax(model) > 0:
        ax.set_yscale("log")
    if pred.extended:
        ax.axvline(t[pred.fit_frames - 1], color="0.5", lw=0.8, ls=":")
    ax.set_ylabel("one-step error (mm)", fontsize=8)
    ax.set_xlabel("frame (of the recording)", fontsize=8)
    ax.tick_params(labelsize=7)
    _time_axis(ax, pred, first_frame, start_time, fontsize=7)
    ax.legend(fontsize=7, loc="best")
    note = "  (dotted line: end of the fitted window)" if pred.extended else ""
    ax.set_title("One-step error of each frame, RMS over the markers" + note, fontsize=9)
    return fig


def burn_in_curve(found, stem: str | Path) -> list[Path]:
    """The free runs after a burn-in (:class:`~activebonds.identify.judge.burn_in.BurnIn`):
    the RMS error k frames after the start, the model's beside zero force's and, where the
    recording is rhythmic, its mean gait's."""
    fig, ax = _subplots(figsize=(8.0, 2.8), layout="constrained")
    k = np.arange(1, found.horizon + 1)
    curves = [("zero force", found.zero_force_mm, ZERO_FORCE), ("model", found.model_mm, FREE_RUN)]
    if found.template_mm is not None:
        curves.insert(1, ("the recording's mean gait", found.template_mm, "tab:green"))
    for label, values, color in curves:
        ax.plot(k, np.asarray(values, np.float64), color=color, lw=1.2, label=label)
    ax.axhline(found.threshold_mm, color="0.5", lw=0.8, ls=":")
    ax.set_yscale("log")
    ax.set_xlabel("frames after the start", fontsize=8)
    ax.set_ylabel("RMS error (mm)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="best")
    ax.set_title(
        f"Free runs after a {found.frames}-frame burn-in ({len(found.starts)} starts; dotted: "
        f"{found.threshold_mm:g} mm)",
        fontsize=9,
    )
    return save(fig, stem)


def activations(
    pred: Prediction,
    labels: Sequence[str],
    stem: str | Path,
    *,
    first_frame: int = 0,
    start_time: float = 0.0,
) -> list[Path]:
    """Neuron activations along the free run, with the saturation limits (|a| = 0.95),
    against the frame number in the recording (time on top)."""
    fig, ax = _subplots(figsize=(7.5, 3.0), layout="constrained")
    frames = frame_numbers(pred, first_frame)
    for b in np.flatnonzero(pred.neural):
        ax.plot(frames, pred.activation[:, b], lw=1.3, label=f"neuron {labels[b]}")
    for y in (-0.95, 0.95):
        ax.axhline(y, color="0.5", lw=0.8, ls=":")
    if pred.extended:
        ax.axvline(frames[pred.fit_frames - 1], color="0.5", lw=0.8, ls=":")
    ax.set_ylim(-1.05, 1.05)
    ax.set_xlabel("frame (of the recording)")
    _time_axis(ax, pred, first_frame, start_time)
    ax.set_ylabel("activation a")
    share = pred.saturated_share
    sat = f"{100 * share:.0f} % of samples saturated" if np.isfinite(share) else "no neuron"
    ax.set_title(f"Neuron activations along the free run ({sat})", fontsize=10)
    if pred.neural.any():
        ax.legend(fontsize=7, loc="lower right")
    ax.grid(True, alpha=0.3)
    return save(fig, stem)
