"""The model's fill of marker gaps: its trajectory, with its parameters fixed, fitted to the
markers present around each gap by multiple shooting with the missing samples masked.

Each gap to fill (:func:`activebonds.data.fill.plan_fill`) is given ``context`` frames on each
side; gaps whose stretches overlap are fitted together, as one segment. A segment is cut into
shooting windows of ``horizon`` frames (:func:`.shooting.shooting_windows`); the windows' start
states are the unknowns, the model's parameters are the model file's values (a fit's
``best_model.toml``). The residuals are those of :func:`.shooting.make_shooting`: every present
sample of every chosen marker, and the continuity defects that make the windows one trajectory
of the model. The states are solved (:mod:`.segment`) by Levenberg-Marquardt (:func:`.lm.levenberg_marquardt`)
on the structured normal equations of :mod:`.shooting_normal`, the parameters held fixed (their
block is never solved: only the block-tridiagonal state system is), from the record's states
(gaps linearly interpolated, central-difference velocities). The model's positions are written
into the gaps; with ``denoise`` the whole window is one segment and its positions are written
everywhere.

The uncertainty of a filled sample starts from the Gauss-Newton standard error of the fitted
position (3-D, the square root of the trace of its covariance): ``s^2 G T^-1 G^T``, with ``T``
the states' J^T J at the solution and ``G`` the position's derivative with respect to its
window's start state. That posterior assumes the model is right; the residuals of the fit on
the present samples around the gap say how far it is not, and scale it (:func:`.uncertainty.error_scale`):

* ``s = max(sigma_noise, sigma_fit)``: ``sigma_fit^2`` the residuals' variance (sum of squares
  over the residuals less the unknowns: positions and continuity defects), ``sigma_noise`` the
  markers' noise estimated from the record alone (:func:`.uncertainty.noise_estimate`: the fourth difference
  of the present samples, robustly). A fit closer to the markers than their noise (a model
  that explains little, its low continuity weight letting the trajectory follow the noise) is
  given the noise: the posterior SD at the noise estimate times ``max(1, sqrt(chi^2 / dof))``
  of the context residuals in units of it;
* times ``sqrt(tau)``, ``tau`` the integrated autocorrelation of the continuity defects in
  position (``1 + 2 sum rho_lag`` over lags up to the segment's longest gap, while ``rho`` is
  positive): a right model leaves white defects (``tau`` about 1), which the posterior
  assumes; a wrong one leaves the same defect frame after frame, whose sum across a gap grows
  with its length rather than its square root.

So a model that explains the context leaves the standard error as it was, and a wrong model's
fill reports an uncertainty of the order of its error (tests/test_fill.py measures both).

``prior="pca"`` (``fill --prior pca``) fuses the model with the correlation of the markers:
after the model's own fit, each stretch is fitted again (from that solution) with the PCA fill
of the missing samples (Gløersen & Federolf 2016) as soft observations (:func:`.prior.pca_prior`):
its positions, and its steps from one frame to the next inside the gap (horizon 1 only), each
weighed ``level / sigma`` against a recorded sample (:func:`.prior.prior_weight`): ``level`` the first
fit's scaled residual SD (what a position error of weight 1 stands for), ``sigma`` the PCA
fill's own error on artificial gaps of the same marker and length, inflated by its
autocorrelation along the gap. Where the PCA fill is unsure, the model's dynamics and the
markers present decide; where the model is unsure (long gaps, a hoof in a trot), the PCA fill
does. The second fit's positions and uncertainties are the fill's; the first fit's positions
are kept (``ModelFill.pure``).

An entrained drive's phase (``[drive] coupling``) is not a variable of the fill: it is
tracked along the record from the start phase at the recording's first frame (the
model's time origin, also where ``--frames`` starts later) (:func:`.dynamics.fill_phases`), as a fit
tracks it, and each shooting window starts from its frame's
tracked phase. Through a gap in the signal's own marker the phase is first run at the drive's
frequency (the coupling off), then tracked along the model's fill of the signal and the
stretch refitted, until the phase stops moving (:data:`PHASE_ROUNDS`): the phase is the
model's state, driven by the model's own trajectory where the record says nothing.

The states' Levenberg-Marquardt steps are solved by LAPACK (:class:`.states.LapackStep`), damped
from 1e-3 of Marquardt's diagonal: on the 41-marker human walk a 30-frame gap took 23 steps
from a damping of 1 (velocities, whose defects weigh dt times a position's, moved a third
further each step), 8-20 now.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field

import jax.numpy as jnp
import numpy as np

from ...data.fill import FillPlan
from ...errors import InputError
from ...model.model import Model
from ...physics import phase
from ...runtime import float64
from ..costs.shooting import CONTINUITY_WEIGHT, frame_states
from .dynamics import continuity_weight, fill_phases, one_step_ratio
from .prior import pca_prior, prior_weight
from .segment import fit_segment
from .settings import MAX_STEPS, PRIORS

HORIZON = 1  # frames per shooting window: every frame's state its own unknown
PHASE_ROUNDS = 8  # refits of a stretch whose entrained drive's signal has a gap, at most
PHASE_TOL = 1e-9  # radians: the rounds stop when the tracked phase moves less
TAU_NOTE = 4.0  # the note names correlated continuity defects from this tau up (scale 2)


@dataclass(frozen=True, eq=False)
class Segment:
    """One fitted stretch of the window: frames ``start:stop`` (window frames)."""

    start: int
    stop: int
    steps: int
    message: str
    rms_mm: float  # of the present samples, at the solution
    continuity: float = CONTINUITY_WEIGHT  # weight of a continuity defect
    scale: float = 1.0  # the posterior SD's scale (:func:`.uncertainty.error_scale`)
    tau: float = 1.0  # the continuity defects' integrated autocorrelation (the model's own fit)
    prior_weight: float = float("nan")  # the median weight of a prior sample; NaN: no prior

    def record(self) -> dict:
        return {
            "prior_weight": self.prior_weight,
            "continuity": self.continuity,
            "frames": f"{self.start}:{self.stop}",
            "steps": self.steps,
            "message": self.message,
            "rms_mm": self.rms_mm,
            "uncertainty_scale": self.scale,
            "defect_correlation": self.tau,
        }


@dataclass(frozen=True, eq=False)
class ModelFill:
    values: np.ndarray  # [F, M, D] window positions: the model's where fitted, else the record's
    uncertainty: list  # per gap to fill (the plan's order): metres per sample
    segments: list[Segment] = field(default_factory=list)
    pure: np.ndarray | None = None  # with a prior: the values of the fit without it

    def note(self) -> str | None:
        if not self.segments:
            return None
        steps = sum(s.steps for s in self.segments)
        worst = max((s.rms_mm for s in self.segments), default=float("nan"))
        unconverged = [s for s in self.segments if not s.message.startswith("converged")]
        text = (
            f"the model's trajectory fitted on {len(self.segments)} stretch(es) "
            f"({steps} Levenberg-Marquardt steps); RMS error at the markers present: "
            f"{worst:.3g} mm at most"
        )
        if unconverged:
            text += f"; {len(unconverged)} not converged ({unconverged[0].message})"
            if "step limit" in unconverged[0].message:
                text += "; raise the limit with --max-steps"
        weights = [s.prior_weight for s in self.segments if np.isfinite(s.prior_weight)]
        if weights:
            text += (
                f"; the PCA fill weighed in as a prior on {len(weights)} stretch(es) (weight "
                f"{min(weights):.2g} to {max(weights):.2g} against a recorded sample)"
            )
        tau = max(s.tau for s in self.segments)
        if tau >= TAU_NOTE:
            text += (
                f"; the model's continuity defects around the gaps are correlated (tau up to "
                f"{tau:.3g}): it does not explain the motion there, and the uncertainties are "
                f"scaled by sqrt(tau)"
            )
        return text


def segments_of(gaps, n_frames: int, context: int) -> list[tuple[int, int]]:
    """The stretches fitted: each gap with ``context`` frames on each side (clipped to the
    window), overlapping ones merged; in order."""
    spans = sorted((max(0, g.start - context), min(n_frames, g.stop + context)) for g in gaps)
    merged: list[list[int]] = []
    for a, b in spans:
        if merged and a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append([a, b])
    return [(a, b) for a, b in merged]


@float64
def model_fill(
    model: Model,
    plan: FillPlan,
    context: int = 30,
    horizon: int = HORIZON,
    substeps: int = 1,
    integrator: str = "euler",
    denoise: bool = False,
    max_steps: int = MAX_STEPS,
    continuity: float | None = None,
    prior: str | None = None,
) -> ModelFill:
    """The model's fill of the plan's gaps (see the module docstring). ``prior="pca"``: each
    stretch is fitted again from the model's solution with the PCA fill of the missing
    samples as soft position errors (:func:`.prior.pca_prior`, weights
    :func:`.prior.prior_weight` at the first fit's scaled residual SD): the model's dynamics
    and the markers present decide where the PCA fill is unsure; ``ModelFill.pure`` keeps the
    first fit's values.

    Raises:
        InputError: the model's trajectory goes non-finite from the record's states; an
            unknown prior; ``prior="pca"`` without complete frames.
    """
    if prior is not None and prior not in PRIORS:
        raise InputError("--prior", f"expected {', '.join(PRIORS)}, got '{prior}'")
    positions, mask = plan.positions, plan.mask
    n_frames, n_markers, _ = positions.shape
    gaps = plan.local()
    values = np.array(positions)
    if not gaps and not denoise:
        return ModelFill(values, [])
    guide = pca_prior(positions, mask, gaps) if prior == "pca" and gaps else None
    pure = np.array(positions) if guide is not None else None
    spans = [(0, n_frames)] if denoise else segments_of(gaps, n_frames, context)
    run = _Run(model, plan, horizon, substeps, integrator, max_steps)
    sigma = np.zeros((n_frames, n_markers))
    segments = []
    for a, b in spans:
        weight = continuity if continuity is not None else run.continuity(a, b)
        inside = [g.stop - g.start for g in gaps if a <= g.start and g.stop <= b]
        fit = run.fit(a, b, weight, longest=max(inside, default=b - a))
        found = fit()
        if run.psi is not None and not mask[a:b][:, run.signal].all():
            found = run.track_signal_gap(a, b, fit, found, values)
        # the note on the model's continuity defects speaks of the model's own fit: a prior's
        # steady pull correlates the defects even of a true model
        model_tau, prior_w = found[3].tau, float("nan")
        if guide is not None:
            pure[a:b] = found[0]
            found, prior_w = _with_prior(fit, found, guide, a, b)
        xs, sd, _, solved = found
        segments.append(
            Segment(
                a,
                b,
                solved.steps,
                solved.message,
                solved.rms_mm,
                continuity=weight,
                scale=solved.scale,
                tau=model_tau,
                prior_weight=prior_w,
            )
        )
        values[a:b] = xs
        sigma[a:b] = sd
    if not denoise:
        # only the gaps are the model's: elsewhere the record stays as it was
        keep = mask.copy()
        values[keep] = positions[keep]
        if pure is not None:
            pure[keep] = positions[keep]
    uncertainty = [sigma[g.start : g.stop, g.column] for g in gaps]
    return ModelFill(values, uncertainty, segments, pure=pure)


class _Run:
    """What the stretches of one fill share: the model at its file's values, the record's
    states, an entrained drive's phase tracked along the window (``psi``, None without one;
    ``psi0`` its value at the window's first frame) and the frames already filled."""

    def __init__(self, model, plan, horizon, substeps, integrator, max_steps):
        self.model, self.plan = model, plan
        self.options = (horizon, substeps, integrator, max_steps)
        self.dt = plan.traj.dt
        # every marker is present somewhere
        self.states = frame_states(plan.positions, plan.mask, self.dt)
        self.genome = jnp.asarray(model.layout.initial())
        # the model's time starts at the recording's first frame: a window that starts later
        # starts from the phase tracked along the frames before it
        self.psi0 = None
        if phase.entrained(model.topology) and plan.window[0] > 0:
            first, cols = plan.window[0], list(plan.columns)
            ahead = plan.traj.positions[: first + 1][:, cols]
            mask_ahead = plan.traj.mask[: first + 1][:, cols]
            self.psi0 = fill_phases(model, self.genome, ahead, mask_ahead, self.dt, substeps)[-1]
        self.psi = self._track(plan.positions, plan.mask)
        self.signal = [] if self.psi is None else list(model.topology.drive.read)
        self.before = np.zeros_like(plan.mask)  # the frames of the segments already filled

    def _track(self, positions, mask):
        substeps = self.options[1]
        return fill_phases(self.model, self.genome, positions, mask, self.dt, substeps, self.psi0)

    def phases(self, a, b):
        return None if self.psi is None else self.psi[a:b]

    def continuity(self, a, b) -> float:
        """The continuity weight of stretch ``a:b``, from how much of its accelerations the
        model explains (:func:`.dynamics.continuity_weight`)."""
        _, substeps, integrator, _ = self.options
        p, m = self.plan.positions[a:b], self.plan.mask[a:b]
        first = self.plan.window[0] + a
        ratio = one_step_ratio(
            self.model, self.genome, p, m, self.dt, first, substeps, integrator, self.phases(a, b)
        )
        return continuity_weight(ratio)

    def fit(self, a, b, weight, longest):
        """:func:`.segment.fit_segment` of stretch ``a:b`` at the phases tracked so far, its
        other arguments (a prior, a start, new phases) to give."""
        horizon, substeps, integrator, max_steps = self.options
        x_all, v_all = self.states
        return functools.partial(
            fit_segment,
            self.model,
            self.genome,
            self.plan.positions[a:b],
            self.plan.mask[a:b],
            (x_all[a:b], v_all[a:b]),
            self.dt,
            self.plan.window[0] + a,
            horizon,
            substeps,
            integrator,
            max_steps,
            weight / CONTINUITY_WEIGHT,
            longest=longest,
            phases=self.phases(a, b),
        )

    def track_signal_gap(self, a, b, fit, found, values):
        """The fit of stretch ``a:b`` where the drive's signal has a gap: the phase tracked
        along the model's fill of it and the stretch refitted, until the two agree (at most
        :data:`PHASE_ROUNDS` rounds)."""
        mask = self.plan.mask
        seen = mask | self.before
        seen[a:b] = True
        xs, sd, z, solved = found
        for _ in range(PHASE_ROUNDS):
            values[a:b][~mask[a:b]] = xs[~mask[a:b]]
            moved = self.psi
            self.psi = self._track(values, seen)
            if np.abs(self.psi[a:b] - moved[a:b]).max() < PHASE_TOL:
                break
            steps = solved.steps
            xs, sd, z, solved = fit(phases=self.psi[a:b], start=z)
            solved = dataclasses.replace(solved, steps=steps + solved.steps)
        self.before[a:b] = True
        return xs, sd, z, solved


def _with_prior(fit, found, guide, a, b):
    """(the fit of stretch ``a:b`` again, from ``found``, with the PCA fill as a prior; the
    median weight of a prior sample), or (``found``, NaN) where the prior weighs nothing."""
    solved, z = found[3], found[2]
    w = prior_weight(solved.level, guide[1][a:b])
    w_step = prior_weight(solved.level, guide[2][a:b])
    if not np.any(w > 0):
        return found, float("nan")
    xs, sd, z, again = fit(guide=(guide[0][a:b], w, w_step), start=z)
    again = dataclasses.replace(again, steps=solved.steps + again.steps)
    return (xs, sd, z, again), float(np.median(w[w > 0]))
