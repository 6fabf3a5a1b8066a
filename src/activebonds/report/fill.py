"""The report of a ``fill`` run: one self-contained HTML page (``fill --report PAGE.html``) whose
figure draws, per filled gap, the recording around the gap, the samples the run filled and the
cubic spline's fill of the same gap beside them, each coordinate in its own colour, with a table
of the gaps (filled or left, and the largest distance between the run's fill and the spline's).

The figure is matplotlib's (object API, drawn by Agg, as :mod:`.plots`), embedded as a base64
PNG: the page needs no other file.
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import numpy as np

from ..data.fill import FillPlan, fill_baseline
from ..data.orientation import AXES
from ..errors import InputError

CONTEXT = 30  # frames of the recording drawn on each side of a gap
COLUMNS = 2  # panels per row


def check_page(path: Path | None) -> None:
    """Refuse (:class:`InputError`, naming ``--report``) a page that is not .html or whose
    folder does not exist, before anything is filled; None: no page."""
    if path is None:
        return
    if path.suffix.lower() not in (".html", ".htm"):
        raise InputError("--report", f"expected an .html page, got '{path.name}'")
    if not path.absolute().parent.is_dir():
        raise InputError("--report", f"the folder of {path} does not exist")


def fill_figure(plan: FillPlan, values: np.ndarray, method: str, spline: np.ndarray | None = None):
    """The matplotlib figure: one panel per gap the run filled (the plan's order), or ``None``
    when nothing was filled. ``values`` [F, M, D] are the run's window positions."""
    from .plots import _subplots

    gaps = plan.local()
    if not gaps:
        return None
    if spline is None:
        spline = fill_baseline("spline", plan.positions, plan.mask, gaps)
    rows = -(-len(gaps) // COLUMNS)
    cols = min(COLUMNS, len(gaps))
    fig, axes = _subplots(
        rows, cols, figsize=(5.5 * cols, 3.2 * rows), layout="constrained", squeeze=False
    )
    frames = np.arange(plan.positions.shape[0]) + plan.window[0]
    dim = plan.positions.shape[2]
    colours = ("C0", "C1", "C2")
    for i, g in enumerate(gaps):
        ax = axes[i // COLUMNS][i % COLUMNS]
        a, b = max(0, g.start - CONTEXT), min(len(frames), g.stop + CONTEXT)
        present = plan.mask[a:b, g.column]
        inside = slice(g.start - 1, g.stop + 1)  # joined to the samples either side
        for d in range(dim):
            c = colours[d % len(colours)]
            rec = np.where(present, plan.positions[a:b, g.column, d], np.nan)
            ax.plot(frames[a:b], rec * 1000.0, color=c, lw=1.0, label=f"{AXES[d].lower()} recorded")
            ax.plot(
                frames[inside],
                values[inside, g.column, d] * 1000.0,
                color=c,
                lw=2.4,
                label=f"{AXES[d].lower()} {method}",
            )
            if method != "spline":
                ax.plot(
                    frames[inside],
                    spline[inside, g.column, d] * 1000.0,
                    color=c,
                    lw=1.2,
                    ls="--",
                    label=f"{AXES[d].lower()} spline",
                )
        ax.axvspan(frames[g.start] - 0.5, frames[g.stop - 1] + 0.5, color="0.9", zorder=0)
        ax.set_title(f"{g.marker}, frames {frames[g.start]}:{frames[g.stop - 1] + 1}", fontsize=9)
        ax.set_xlabel("frame")
        ax.set_ylabel("position (mm)")
        ax.tick_params(labelsize=8)
        if i == 0:
            ax.legend(fontsize=6, ncols=dim, loc="best")
    for j in range(len(gaps), rows * cols):
        axes[j // COLUMNS][j % COLUMNS].set_visible(False)
    return fig


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, metadata={"Software": None})
    return base64.b64encode(buf.getvalue()).decode("ascii")


def fill_report(
    plan: FillPlan, values: np.ndarray, method: str, source: str, note: str | None = None
) -> str:
    """The HTML page of a fill run (see the module docstring)."""
    gaps = plan.local()
    spline = fill_baseline("spline", plan.positions, plan.mask, gaps) if gaps else None
    fig = fill_figure(plan, values, method, spline)
    first = plan.window[0]
    rows = []
    for g, local in zip(plan.to_fill, gaps, strict=True):
        cut = slice(local.start, local.stop)
        apart = np.linalg.norm(values[cut, local.column] - spline[cut, local.column], axis=-1)
        rows.append(
            (g.marker, f"{g.start}:{g.stop}", g.length, "filled", f"{apart.max() * 1e3:.3g}")
        )
    for g in plan.left:
        rows.append((g.marker, f"{g.start}:{g.stop}", g.length, f"left: {g.reason}", "—"))
    cells = "\n".join(
        "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows
    )
    figure = (
        f'<img src="data:image/png;base64,{_png(fig)}" alt="the filled gaps" '
        f'style="max-width:100%">'
        if fig is not None
        else "<p>No gap was filled.</p>"
    )
    title = f"activebonds fill: {html.escape(source)} ({html.escape(method)})"
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>body{{font-family:sans-serif;margin:1.5em;max-width:72em}}
table{{border-collapse:collapse}}td,th{{border:1px solid #bbb;padding:.2em .6em}}</style>
</head><body>
<h1>{title}</h1>
<p>Window from frame {first}; {len(gaps)} gap(s) filled by {html.escape(method)},
{len(plan.left)} left.{" " + html.escape(note) if note else ""}</p>
<h2>The filled gaps</h2>
<p>Per gap: the recording ({CONTEXT} frames either side, thin), the samples filled by
{html.escape(method)} (thick) and the cubic spline's fill of the same gap (dashed), per
coordinate; the gap shaded.</p>
{figure}
<h2>Gaps</h2>
<table><tr><th>marker</th><th>frames</th><th>length</th><th>status</th>
<th>largest distance from the spline's fill (mm)</th></tr>
{cells}
</table>
</body></html>
"""
