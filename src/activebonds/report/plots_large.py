"""The report's figures for a large model or body, in a fixed size: above
:data:`LABELLED` parameters their figure is a dot each without labels (a labelled bar each
would make it hundreds of inches tall and minutes to draw); above :data:`SHOWN` markers the
trajectories figure shows the markers predicted worst one step (a panel per marker and axis:
123 panels for a 41-marker body)."""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

SHOWN = 12  # markers in the trajectories figure, at most


def largest(scores) -> list[int]:
    """Every index of ``scores`` [P] up to :data:`SHOWN` of them, else the :data:`SHOWN`
    with the largest scores (NaN last), in file order."""
    score = np.nan_to_num(np.asarray(scores, np.float64), nan=-np.inf)
    if score.size <= SHOWN:
        return list(range(score.size))
    return sorted(int(i) for i in np.argsort(-score, kind="stable")[:SHOWN])


def shown_particles(pred) -> list[int]:
    """The particles of the trajectories figure: every one up to :data:`SHOWN`, else the
    :data:`SHOWN` with the largest one-step RMS on the fitted frames (a particle with none
    last), in file order."""
    return largest(pred.one_step_rms_mm)


# above this many parameters, one figure of fixed size without a label per parameter (a bar
# each would make it hundreds of inches tall, and minutes to draw); the values are in the
# report's table of parameters
LABELLED = 80


def parameters_compact(rows, title: str):
    """Every parameter's position within its bounds as a dot, in file order (red within 1 %
    of a bound), on a figure of fixed size (unsaved)."""
    n = len(rows)
    pos = np.clip(np.nan_to_num(np.array([r.position for r in rows]), nan=0.5), 0.0, 1.0)
    edge = np.array([r.bound is not None for r in rows])
    fig = Figure(figsize=(7.5, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.scatter(pos, np.arange(n)[::-1], color=np.where(edge, "tab:red", "tab:blue"), s=5)
    ax.set_xlim(-0.02, 1.02)
    ax.set_xticks([0, 0.5, 1], ["min", "mid", "max"])
    ax.set_yticks([])
    ax.set_ylabel(f"{n} parameters, in the model file's order")
    ax.set_xlabel("position within the bounds (search space; log genes on a log scale)")
    ax.set_title(f"{title}: {int(edge.sum())} of {n} within 1 % of a bound (red)")
    return fig
