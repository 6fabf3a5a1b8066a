"""Do the uncertainty report's 95 % intervals contain the truth 95 % of the time?

One trial: simulate a model (the truth) with this package, add independent Gaussian noise to
every marker coordinate, fit it from the data alone (the exact one-step least squares as the
start, then Levenberg-Marquardt on the restart cost at a horizon of 10 frames, then on one
shooting window over the whole recording, i.e. an output-error fit with the start state free), and compute the Gauss-Newton intervals
(:mod:`activebonds.identify.judge.uncertainty`). Over many noise seeds, the share of intervals
that contain the true value estimates their coverage.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..identify.costs.windows import make_windows
from ..identify.judge.uncertainty import Uncertainty, estimate
from ..identify.problem import identification
from ..identify.settings import FitSettings
from ..identify.solvers.lsq import least_squares
from ..identify.solvers.refine import Refinement
from ..model import Model
from ..simulation import simulate

SHORT = 10  # horizon of the first stage (the restart cost: genes only, cheap, less biased)


@dataclass
class Trial:
    seed: int
    names: list[str]
    truth: list[float]
    values: list[float]
    std_errors: list[float | None]
    inside: list[bool]  # the 95 % interval contains the truth (False when not determined)
    rms_mm: float
    message: str  # the refinement's last line


def trial(model: Model, n_frames: int, rate: float, noise_m: float, seed: int) -> Trial:
    """Simulate, add noise (std ``noise_m`` metres per coordinate), fit, and compare."""
    layout = model.layout
    truth = layout.natural(layout.initial())
    clean = simulate(model, n_frames, rate)
    rng = np.random.default_rng(seed)
    noisy = clean.with_positions(clean.positions + rng.normal(0.0, noise_m, clean.positions.shape))
    settings = FitSettings(horizon=(SHORT, n_frames), cost="shooting", refine="lm")
    ident = identification(model, noisy, settings)
    start = least_squares(ident.model, make_windows(noisy.positions, noisy.mask, noisy.dt, 1))
    refinement = Refinement(ident, settings)
    restart = FitSettings(horizon=(SHORT,), cost="restart", refine="lm")
    first = Refinement(ident, restart).stage(SHORT, start.genome)
    stage = refinement.stage(n_frames, np.asarray(first.genome))
    report: Uncertainty = estimate(
        ident, settings, np.asarray(stage.genome), n_frames, "shooting", refinement.states
    )
    inside = [
        bool(e.determined and e.low <= t <= e.high)
        for e, t in zip(report.estimates, truth, strict=True)
    ]
    return Trial(
        seed=seed,
        names=[e.name for e in report.estimates],
        truth=[float(t) for t in truth],
        values=[e.value for e in report.estimates],
        std_errors=[e.std_error for e in report.estimates],
        inside=inside,
        rms_mm=stage.end_rms_mm,
        message=stage.message,
    )


def coverage(trials: list[Trial]) -> float:
    """The share of all intervals (every parameter of every trial) that contain the truth."""
    flags = [f for t in trials for f in t.inside]
    return float(np.mean(flags)) if flags else float("nan")
