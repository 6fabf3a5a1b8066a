"""The gait's figures (:mod:`activebonds.report.gait_runs`): the feet's heights against the
recording's frame number and one stride's heights against its phase, the recording in black
and the model's free runs in orange (:mod:`~activebonds.report.plots`' colours)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..identify.judge.predictions import to_mm
from .plots import FREE_RUN, RECORDED, _limits, _subplots, save
from .plots_large import largest


def _free_run_line(ax, x, y, first: bool, label: str) -> None:
    """One of the model's free runs (orange, thin), ``label`` on the first one only."""
    ax.plot(x, y, color=FREE_RUN, lw=0.9, alpha=0.6, label=label if first else None)


def gait_heights(found, stem: str | Path, *, first_frame: int = 0) -> list[Path]:
    """The feet's heights (mm, along up) against the recording's frame number: the recorded
    window (black) and each free run of the model (orange, from its start frame, past the
    window's end where it runs on). ``found``: a
    :class:`~activebonds.report.gait_runs.GaitEvaluation`; the y range follows the
    recording."""
    from . import gait as g

    ref = found.recording
    rec = g.vertical(found.recorded, ref.up)
    feet = list(ref.feet)
    fig, axes = _subplots(
        len(feet),
        1,
        figsize=(9.0, 1.6 * len(feet) + 0.9),
        sharex=True,
        squeeze=False,
        layout="constrained",
    )
    t0 = int(first_frame)
    for row, (foot, name) in enumerate(zip(feet, found.feet, strict=True)):
        ax = axes[row, 0]
        h = to_mm(rec[:, foot])
        ax.plot(t0 + np.arange(len(h)), h, color=RECORDED, lw=1.5, label="recorded")
        for i, (s, run) in enumerate(zip(found.starts, found.model_runs, strict=True)):
            frames = t0 + s + 1 + np.arange(run.shape[0])
            y = to_mm(g.vertical(run, ref.up)[:, foot])
            _free_run_line(ax, frames, y, i == 0, "model's free runs")
        if np.isfinite(h).any():
            ax.set_ylim(*_limits(h))
        ax.set_ylabel(f"{name} (mm)", fontsize=9)
        ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("frame (of the recording)", fontsize=8)
    fig.suptitle(
        f"Feet heights: recorded vs {len(found.starts)} free runs of {found.run_frames} frames",
        fontsize=10,
    )
    return save(fig, stem)


def most_moving(heights: np.ndarray) -> list[int]:
    """The markers of a gait figure: every one up to :data:`~.plots_large.SHOWN`, else the
    :data:`~.plots_large.SHOWN` whose height ``heights`` [bins, P] varies most over the
    stride (the legs and feet, what a gait is; a marker never seen last), in file order."""
    seen = np.isfinite(heights)
    high = np.where(seen, heights, -np.inf).max(axis=0)
    low = np.where(seen, heights, np.inf).min(axis=0)
    return largest(np.where(seen.any(axis=0), high - low, np.nan))


def gait_cycle(found, stem: str | Path) -> list[Path]:
    """One panel per particle: its height (mm, along up) over one stride (phase 0-1) in the
    recording's mean gait (black) and each free run's cycle average after its best phase
    shift (orange), as (iv) compares them."""
    from . import gait as g

    ref = found.recording
    names = found.particles
    phase = np.arange(g.PHASE_BINS) / g.PHASE_BINS
    mean_h = to_mm(g.vertical(ref.gait, ref.up))  # [bins, P]
    shown = most_moving(mean_h)
    n = len(shown)
    cols = min(n, 4)
    rows = math.ceil(n / cols)
    fig, axes = _subplots(
        rows,
        cols,
        figsize=(2.6 * cols + 0.6, 2.0 * rows + 0.9),
        squeeze=False,
        layout="constrained",
    )
    averages = []
    for run, score in zip(found.model_runs, found.model.runs, strict=True):
        if not np.isfinite(run).all():
            continue
        t = score.period_frames if np.isfinite(score.period_frames) else ref.period_frames
        avg = g.cycle_average(run, t)
        if np.isfinite(avg).all():
            averages.append(np.roll(avg, g.best_shift(avg, ref.gait)[0], axis=0))
    for k in range(rows * cols):
        ax = axes[k // cols, k % cols]
        if k >= n:
            ax.set_visible(False)
            continue
        p = shown[k]
        for i, avg in enumerate(averages):
            y = to_mm(g.vertical(avg, ref.up)[:, p])
            _free_run_line(ax, phase, y, i == 0, "model's cycle averages")
        ax.plot(phase, mean_h[:, p], color=RECORDED, lw=1.8, label="recorded mean gait")
        if np.isfinite(mean_h[:, p]).any():
            ax.set_ylim(*_limits(mean_h[:, p]))
        ax.set_title(names[p], fontsize=9)
        ax.tick_params(labelsize=7)
        if k % cols == 0:
            ax.set_ylabel("height (mm)", fontsize=8)
        if k // cols == rows - 1:
            ax.set_xlabel("phase (strides)", fontsize=8)
    axes[0, 0].legend(fontsize=6, loc="best")
    some = (
        f"\nthe {n} of {len(names)} markers whose height varies most over the stride"
        if n < len(names)
        else ""
    )
    fig.suptitle(
        "One stride: the recorded mean gait and the free runs' cycle averages (best phase)" + some,
        fontsize=10,
    )
    return save(fig, stem)
