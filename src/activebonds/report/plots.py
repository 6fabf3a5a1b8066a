"""Report figures (matplotlib's object API, drawn by Agg; the backend is left alone): each function writes ``STEM.png`` and ``STEM.svg`` and
returns both paths, PNG first.

Colours: the recording is black, one-step predictions blue, the free run orange; series of a
comparison take the default colour cycle in order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import matplotlib.ticker as mticker
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import TwoSlopeNorm
from matplotlib.figure import Figure

from ..identify.operators import VARIANTS
from ..model import Model
from ..model.names import bound_position, parameter_label, parameter_rows
from .predict import Prediction, neural_bonds, neural_weights, to_mm
from .runs import history_rms_mm

RECORDED = "black"
ONE_STEP = "tab:blue"
FREE_RUN = "tab:orange"
AXES = "XYZ"
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
    baseline, an exact optimum, a floor) where they fall within 100x of the curves."""
    fig, ax = _subplots(figsize=(7.5, 4.2), layout="constrained")
    colors = matplotlib.rcParams["axes.prop_cycle"].by_key()["color"]
    if band is None:
        band = any(len(s.histories) > 1 for s in series)
    drawn = False
    for i, s in enumerate(series):
        color = colors[i % len(colors)]
        rms = [history_rms_mm(h) for h in s.histories]
        if not rms or all(len(r["best"]) == 0 for r in rms):
            continue
        best, median = _stack([r["best"] for r in rms]), _stack([r["median"] for r in rms])
        gens = np.arange(1, best.shape[1] + 1)
        n = len(rms)
        if band and n > 1:
            q = _nanpercentile(best, [25, 50, 75])
            ax.fill_between(gens, q[0], q[2], color=color, alpha=0.25, linewidth=0)
            ax.plot(gens, q[1], color=color, lw=1.8, label=f"{s.label}: best (median of {n}, IQR)")
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
                ax.plot(
                    gens, median[k], color=color, lw=1, ls="--", label=f"{lab}: population median"
                )
        drawn = True
    if drawn:
        ax.set_yscale("log")
        lo, hi = ax.get_ylim()
        styles = [":", "-.", (0, (5, 2, 1, 2)), (0, (1, 3))]
        for k, (label, value) in enumerate(references):
            if value is None or not np.isfinite(value) or not lo / 100 <= value <= hi * 100:
                continue
            ax.axhline(
                value, color="0.35", lw=1.1, ls=styles[k % len(styles)],
                label=f"{label}: {value:.4g} mm",
            )  # fmt: skip
        plain = mticker.FuncFormatter(lambda v, _: f"{v:g}")
        ax.yaxis.set_major_formatter(plain)
        lo, hi = ax.get_ylim()
        ax.yaxis.set_minor_formatter(plain if hi / lo < 30 else mticker.NullFormatter())
        ax.legend(fontsize=8, loc="upper right")
    else:
        ax.text(
            0.5, 0.5, "no generation recorded", ha="center", va="center", transform=ax.transAxes
        )
    ax.set_xlabel("generation")
    ax.set_ylabel("RMS position error (mm)")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    return save(fig, stem)


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
    fig, ax = _subplots(figsize=(7.5, max(1.6, 0.28 * n + 1.0)), layout="constrained")
    if n == 0:
        ax.text(0.5, 0.5, "no free parameter", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return save(fig, stem)
    searched = {g.name: g for g in (bounds or model).layout.genes}
    genes = [searched.get(g.name, g) for g in model.layout.genes]
    pos = np.array([bound_position(g, r.value) for g, r in zip(genes, rows, strict=True)])
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


def trajectories(
    pred: Prediction, stem: str | Path, *, title: str = "Recorded vs predicted"
) -> list[Path]:
    """One panel per particle and axis (position in mm against time): the recording, the
    one-step predictions and the free run; the end of the fitted window is a vertical line.
    The y range follows the recording, so a diverging free run leaves the panel."""
    n_p, dim = pred.recorded.shape[1], pred.recorded.shape[2]
    fig, axes = _subplots(
        n_p,
        dim,
        figsize=(3.0 * dim + 1, 1.9 * n_p + 0.9),
        sharex=True,
        squeeze=False,
        layout="constrained",
    )
    t = pred.times
    for p in range(n_p):
        for d in range(dim):
            ax = axes[p, d]
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
            if p == 0:
                ax.set_title(f"{AXES[d]} (mm)", fontsize=9)
            if d == 0:
                ax.set_ylabel(pred.names[p], fontsize=9)
            if p == n_p - 1:
                ax.set_xlabel("time (s)", fontsize=8)
    axes[0, 0].legend(fontsize=7, loc="best")
    note = "  (dotted line: end of the fitted window)" if pred.extended else ""
    fig.suptitle(title + note, fontsize=10)
    return save(fig, stem)


def activations(pred: Prediction, labels: Sequence[str], stem: str | Path) -> list[Path]:
    """Neuron activations along the free run, with the saturation limits (|a| = 0.95)."""
    fig, ax = _subplots(figsize=(7.5, 3.0), layout="constrained")
    for b in np.flatnonzero(pred.neural):
        ax.plot(pred.times, pred.activation[:, b], lw=1.3, label=f"neuron {labels[b]}")
    for y in (-0.95, 0.95):
        ax.axhline(y, color="0.5", lw=0.8, ls=":")
    if pred.extended:
        ax.axvline(pred.times[pred.fit_frames - 1], color="0.5", lw=0.8, ls=":")
    ax.set_ylim(-1.05, 1.05)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("activation a")
    share = pred.saturated_share
    sat = f"{100 * share:.0f} % of samples saturated" if np.isfinite(share) else "no neuron"
    ax.set_title(f"Neuron activations along the free run ({sat})", fontsize=10)
    if pred.neural.any():
        ax.legend(fontsize=7, loc="lower right")
    ax.grid(True, alpha=0.3)
    return save(fig, stem)
