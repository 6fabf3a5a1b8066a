"""The model's fill of marker gaps: its trajectory, with its parameters fixed, fitted to the
markers present around each gap by multiple shooting with the missing samples masked.

Each gap to fill (:func:`activebonds.data.fill.plan_fill`) is given ``context`` frames on each
side; gaps whose stretches overlap are fitted together, as one segment. A segment is cut into
shooting windows of ``horizon`` frames (:func:`.shooting.shooting_windows`); the windows' start
states are the unknowns, the model's parameters are the model file's values (a fit's
``best_model.toml``). The residuals are those of :func:`.shooting.make_shooting`: every present
sample of every chosen marker, and the continuity defects that make the windows one trajectory
of the model. The states are solved by Levenberg-Marquardt (:func:`.lm.levenberg_marquardt`)
on the structured normal equations of :mod:`.shooting_normal`, the parameters held fixed (their
block is never solved: only the block-tridiagonal state system is), from the record's states
(gaps linearly interpolated, central-difference velocities). The model's positions are written
into the gaps; with ``denoise`` the whole window is one segment and its positions are written
everywhere.

The uncertainty of a filled sample starts from the Gauss-Newton standard error of the fitted
position (3-D, the square root of the trace of its covariance): ``s^2 G T^-1 G^T``, with ``T``
the states' J^T J at the solution and ``G`` the position's derivative with respect to its
window's start state. That posterior assumes the model is right; the residuals of the fit on
the present samples around the gap say how far it is not, and scale it (:func:`error_scale`):

* ``s = max(sigma_noise, sigma_fit)``: ``sigma_fit^2`` the residuals' variance (sum of squares
  over the residuals less the unknowns: positions and continuity defects), ``sigma_noise`` the
  markers' noise estimated from the record alone (:func:`noise_estimate`: the fourth difference
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
of the missing samples (Gløersen & Federolf 2016) as soft observations (:func:`pca_prior`):
its positions, and its steps from one frame to the next inside the gap (horizon 1 only), each
weighed ``level / sigma`` against a recorded sample (:func:`prior_weight`): ``level`` the first
fit's scaled residual SD (what a position error of weight 1 stands for), ``sigma`` the PCA
fill's own error on artificial gaps of the same marker and length, inflated by its
autocorrelation along the gap. Where the PCA fill is unsure, the model's dynamics and the
markers present decide; where the model is unsure (long gaps, a hoof in a trot), the PCA fill
does. The second fit's positions and uncertainties are the fill's; the first fit's positions
are kept (``ModelFill.pure``).

An entrained drive's phase (``[drive] coupling``) is not a variable of the fill: it is
tracked along the record from the start phase at the recording's first frame (the
model's time origin, also where ``--frames`` starts later) (:func:`fill_phases`), as a fit
tracks it, and each shooting window starts from its frame's
tracked phase. Through a gap in the signal's own marker the phase is first run at the drive's
frequency (the coupling off), then tracked along the model's fill of the signal and the
stretch refitted, until the phase stops moving (:data:`PHASE_ROUNDS`): the phase is the
model's state, driven by the model's own trajectory where the record says nothing.

The states' Levenberg-Marquardt steps are solved by LAPACK (:class:`_LapackStep`), damped
from 1e-3 of Marquardt's diagonal: on the 41-marker human walk a 30-frame gap took 23 steps
from a damping of 1 (velocities, whose defects weigh dt times a position's, moved a third
further each step), 8-20 now.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from ...data.fill import FillPlan
from ...errors import InputError
from ...model.model import Model
from ...physics import phase
from ...physics.integrate import rollout_states
from ...runtime import float64
from ..costs.shooting import (
    CONTINUITY_WEIGHT,
    ShootingWindows,
    frame_states,
    make_shooting,
    shooting_windows,
    start_states,
)
from ..solvers.lm import levenberg_marquardt
from ..solvers.shooting_normal import block_tridiagonal_solve, floored, make_normal

MAX_STEPS = 200
RATIO_FRAMES = 8  # frames ahead of the prediction that sets the continuity weight
HORIZON = 1  # frames per shooting window: every frame's state its own unknown
CONTINUITY = 0.3  # least weight of a continuity defect against a position error (metres each)
RTOL, ATOL = 1e-10, 1e-12
MARQUARDT = True
DAMPING = 1e-3
LAPACK = True
SHAPE = True
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
    scale: float = 1.0  # the posterior SD's scale (:func:`error_scale`)
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


def noise_estimate(positions: np.ndarray, mask: np.ndarray) -> float:
    """The markers' noise (m, per coordinate) from the record alone: the fourth difference of
    every marker's present samples (five consecutive frames), whose standard deviation is
    ``sqrt(70)`` times the noise's for white noise on a motion smooth at the frame rate; its
    median absolute value (over 0.6745, robust to impacts) over ``sqrt(70)``. NaN with fewer
    than 10 such differences."""
    x, m = positions, mask
    ok = m[:-4] & m[1:-3] & m[2:-2] & m[3:-1] & m[4:]
    d4 = x[4:] - 4 * x[3:-1] + 6 * x[2:-2] - 4 * x[1:-3] + x[:-4]
    values = np.abs(d4[ok]).ravel()
    if values.size < 10:
        return float("nan")
    return float(np.median(values) / 0.6745 / np.sqrt(70.0))


def defect_correlation(defects: np.ndarray, longest: int) -> float:
    """The integrated autocorrelation ``tau = 1 + 2 sum rho_lag`` of the continuity defects
    ``defects`` [K, n] (one series per coordinate, each less its mean), over lags 1 to
    ``longest`` - 1 while ``rho`` stays positive; at least 1."""
    e = defects - defects.mean(axis=0)
    v = float(np.mean(e**2))
    if not v > 0.0:
        return 1.0
    tau = 1.0
    for lag in range(1, min(int(longest), len(e))):
        rho = float(np.mean(e[lag:] * e[:-lag])) / v
        if not rho > 0.0:
            break
        tau += 2.0 * rho
    return tau


def error_scale(sigma_fit: float, sigma_noise: float, tau: float) -> float:
    """The factor on the posterior SD at ``sigma_fit`` (see the module's docstring):
    ``max(sigma_noise, sigma_fit) / sigma_fit * sqrt(tau)``; with ``sigma_fit`` 0 (an exact
    fit), 1 (the SD is 0 and the noise floor is applied by the caller)."""
    floor = sigma_noise if np.isfinite(sigma_noise) else 0.0
    level = max(floor, sigma_fit) / sigma_fit if sigma_fit > 0.0 else 1.0
    return float(level * np.sqrt(max(tau, 1.0)))


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


def _states_step(system, damping):
    """The damped Gauss-Newton step of the states alone: (T + D) d = -g_s, D = damping I
    (a number) or diag(damping) ([K, n]: Marquardt's scaling)."""
    n = system.diag.shape[1]
    rhs = -system.grad_s[..., None]
    damp = jnp.asarray(damping)[..., None] * jnp.eye(n)
    return block_tridiagonal_solve(system.diag + damp, system.off, rhs)[..., 0]


_states_step_jit = jax.jit(_states_step)


class _LapackStep:
    """:func:`_states_step` by LAPACK (SciPy), the system copied out of JAX once per
    linearization: on a 41-marker body (blocks of 246) XLA's scan of triangular solves took
    2 s a step, LAPACK 1 s (``benchmarks/gaps.py``'s human walk; docs/experiments/gaps.md)."""

    def __init__(self):
        self._system, self._arrays = None, None

    def __call__(self, system, damping):
        if system is not self._system:
            self._system = system
            self._arrays = tuple(np.asarray(a) for a in (system.diag, system.off, system.grad_s))
        diag, off, grad = self._arrays
        damp = np.asarray(damping)
        if damp.ndim == 0:
            damp = np.full(grad.shape, float(damp))
        k, n = grad.shape
        blocks = diag + damp[..., None] * np.eye(n)
        return jnp.asarray(block_tridiagonal_lapack(blocks, off, -grad))


def block_tridiagonal_lapack(diag: np.ndarray, off: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve T Z = rhs ([K, n]) for a symmetric positive definite block-tridiagonal T
    (``diag`` [K, n, n], ``off`` [K - 1, n, n] = T_k,k+1): the block Cholesky recursion of
    :func:`.shooting_normal.block_tridiagonal_solve`, by LAPACK."""
    from scipy.linalg import cholesky, solve_triangular

    k = len(diag)
    chol = np.empty_like(diag)
    sub = np.zeros_like(diag)  # sub[i] = L_i,i-1
    z = np.empty_like(rhs)
    for i in range(k):
        d, r = diag[i], rhs[i]
        if i:
            sub[i] = solve_triangular(chol[i - 1], off[i - 1], lower=True, check_finite=False).T
            d = d - sub[i] @ sub[i].T
            r = r - sub[i] @ z[i - 1]
        chol[i] = cholesky(d, lower=True, check_finite=False)
        z[i] = solve_triangular(chol[i], r, lower=True, check_finite=False)
    x = np.empty_like(rhs)
    for i in range(k - 1, -1, -1):
        r = z[i] - sub[i + 1].T @ x[i + 1] if i < k - 1 else z[i]
        x[i] = solve_triangular(chol[i], r, lower=True, trans="T", check_finite=False)
    return x


@jax.jit
def _states_diagonal(system):
    """T's diagonal [K, n], floored (:func:`.shooting_normal.floored`): Marquardt's scaling of
    the damping, so that a velocity (whose defect weighs ``dt`` times a position's) is damped
    in its own units."""
    return floored(jnp.diagonal(system.diag, axis1=1, axis2=2))


def inverse_diagonal_blocks(diag: np.ndarray, off: np.ndarray) -> np.ndarray:
    """The diagonal blocks of T^-1 for a symmetric positive definite block-tridiagonal T
    (``diag`` [K, n, n], ``off`` [K - 1, n, n] = T_k,k+1): (L_k + R_k - T_kk)^-1 with L_k, R_k
    the Schur complements of the blocks before and after k."""
    k = len(diag)
    left, right = np.empty_like(diag), np.empty_like(diag)
    left[0] = diag[0]
    for i in range(1, k):
        left[i] = diag[i] - off[i - 1].T @ np.linalg.solve(left[i - 1], off[i - 1])
    right[-1] = diag[-1]
    for i in range(k - 2, -1, -1):
        right[i] = diag[i] - off[i] @ np.linalg.solve(right[i + 1], off[i].T)
    return np.linalg.inv(left + right - diag)


def continuity_weight(ratio: float) -> float:
    """The weight of a continuity defect (against a position error) for a model whose one-step
    error is ``ratio`` times zero force's: ``CONTINUITY / ratio^2`` within
    [``CONTINUITY``, ``CONTINUITY_WEIGHT``]. A model that explains the accelerations (ratio near
    0: the true model, the noise left) is held to its dynamics as the shooting fit holds it; a
    model that explains little of them (ratio near 1) lets the trajectory leave its dynamics
    where the markers present ask for it, at a cost still large enough to carry the missing
    marker through the gap."""
    if not np.isfinite(ratio) or ratio <= 0.0:
        return CONTINUITY_WEIGHT
    return float(np.clip(CONTINUITY / ratio**2, CONTINUITY, CONTINUITY_WEIGHT))


def one_step_ratio(
    model: Model, genome, positions, mask, dt, first, substeps=1, integrator="euler", phases=None
) -> float:
    """How much of the motion's accelerations the model leaves unexplained: on the frames t of
    ``positions`` [S, M, D] where every marker is present at t - n, t and t + n
    (n = ``RATIO_FRAMES``), the RMS of ``x(t+n) - 2 x(t) + x(t-n) - (n dt)^2 F(x, v, t) / m``
    over the RMS of the second difference alone (zero force's), with v the central difference
    over 2 n frames; NaN without such frames. Over several frames the accelerations outgrow
    the marker noise, which a one-frame ratio would measure instead. (``substeps`` and
    ``integrator`` are the fill's; the ratio reads the forces alone. ``phases`` [S]: an
    entrained drive's phase at each frame.)"""
    from ...physics.forces import total_force

    n = RATIO_FRAMES
    if len(positions) <= 2 * n:
        return float("nan")
    ok = mask[: -2 * n].all(1) & mask[n:-n].all(1) & mask[2 * n :].all(1)
    t = np.flatnonzero(ok) + n
    if not t.size:
        return float("nan")
    x, prev, nxt = positions[t], positions[t - n], positions[t + n]
    params = model.layout.decode(genome)
    v = (nxt - prev) / (2 * n * dt)

    def accel(x0, v0, time, *psi):
        held = phase.at_phase(params, psi[0]) if psi else params
        return total_force(held, model.topology, x0, v0, time) / params.mass[:, None]

    extra = () if phases is None else (jnp.asarray(np.asarray(phases)[t]),)
    a = jax.vmap(accel)(jnp.asarray(x), jnp.asarray(v), jnp.asarray((t + first) * dt), *extra)
    a = np.asarray(a)
    second = nxt - 2.0 * x + prev
    e_model = float(np.sqrt(np.mean(np.square(second - (n * dt) ** 2 * a))))
    e_zero = float(np.sqrt(np.mean(np.square(second))))
    return e_model / e_zero if e_zero > 0.0 else float("nan")


def fill_phases(
    model: Model, genome, positions, mask, dt, substeps=1, psi0=None
) -> np.ndarray | None:
    """An entrained drive's phase at every frame [S] of ``positions`` [S, M, D], tracked
    from ``psi0`` (default: the start phase) at the first frame
    (:func:`~activebonds.physics.phase.track`), the coupling off (the signal at its offset)
    wherever the signal's markers are missing: the phase runs at the drive's frequency there.
    None for a model without one."""
    topo = model.topology
    if not phase.entrained(topo):
        return None
    marks = list(topo.drive.read)
    missing = ~np.asarray(mask, bool)[:, marks].all(axis=1)
    s = phase.signal(topo, positions, np)
    s = np.where(missing.reshape(-1, *[1] * (s.ndim - 1)), 0.0, s)
    params = model.layout.decode(genome)
    return np.asarray(phase.track(params, topo, jnp.asarray(s), dt, substeps, psi0))


PRIORS = ("pca",)


def pca_prior(positions: np.ndarray, mask: np.ndarray, gaps):
    """The PCA fill as a prior on the gaps' samples: (targets [F, M, D], the standard
    deviation per coordinate [F, M] that a sample of it is given, that of its motion from
    frame t to t + 1 within the gap [F, M] (at t); NaN off the gaps).

    The targets are Gløersen & Federolf's reconstruction (:func:`.data.fill.fill_pca`). The
    deviation comes from the PCA fill's own errors, cross-validated: the same fill of up to
    ``TRIALS`` artificial gaps of the gap's length and marker placed in complete stretches of
    the record (those frames are then not complete, so never among its training frames;
    :func:`.data.fill.self_test_errors`). Their RMS per coordinate ``sigma`` (floored at the
    markers' noise) is inflated by ``sqrt(tau)``, ``tau`` the errors' integrated
    autocorrelation along the gap (:func:`error_correlation`): the PCA fill's error is an
    offset that drifts slowly, so ``L`` samples of it know about as much as ``L / tau``
    independent ones, and fitted as independent observations they would pull the trajectory
    as if they knew ``tau`` times more. The PCA fill's motion inside the gap (its step from
    one frame to the next) is often better than where it puts the marker (its error is
    mostly an offset): its steps' errors, measured the same way, give the deviation of a
    second prior, on the missing marker's steps. NaN for a gap with no room for a test."""
    from ...data.fill import fill_pca, self_test_errors

    targets = fill_pca(positions, mask, gaps)
    sigma = np.full(mask.shape, np.nan)
    shape = np.full(mask.shape, np.nan)
    noise = noise_estimate(positions, mask)
    floor = noise if np.isfinite(noise) else 0.0
    tested: dict[tuple[int, int], tuple[float, float]] = {}
    for g in gaps:
        key = (g.column, g.length)
        if key not in tested:
            e = self_test_errors(fill_pca, positions, mask, g.column, g.length, others=True)
            if not len(e):
                tested[key] = (float("nan"), float("nan"))
            else:
                rms = max(float(np.sqrt(np.mean(e**2))), floor)
                level = rms * float(np.sqrt(error_correlation(e)))
                steps = np.diff(e, axis=1)  # the errors of its frame-to-frame motion
                if steps.shape[1] and SHAPE:
                    step_rms = max(float(np.sqrt(np.mean(steps**2))), floor * np.sqrt(2.0))
                    step = step_rms * float(np.sqrt(error_correlation(steps)))
                else:
                    step = float("nan")
                tested[key] = (level, step)
        sigma[g.start : g.stop, g.column] = tested[key][0]
        shape[g.start : g.stop - 1, g.column] = tested[key][1]
    return targets, sigma, shape


def error_correlation(errors: np.ndarray) -> float:
    """How many samples of a gap's errors count as one: ``tau = 1 + 2 sum_lag (1 - lag / L)
    rho_lag`` over lags 1 to ``L`` - 1 while ``rho`` stays positive, ``rho_lag`` the errors'
    autocorrelation (about zero, not their mean: an offset is the correlated part), pooled
    over ``errors`` [trials, L, D]; between 1 and ``L`` (a constant offset)."""
    n = errors.shape[1]
    v = float(np.mean(errors**2))
    if not v > 0.0:
        return 1.0
    tau = 1.0
    for lag in range(1, n):
        rho = float(np.mean(errors[:, lag:] * errors[:, :-lag])) / v
        if not rho > 0.0:
            break
        tau += 2.0 * (1.0 - lag / n) * rho
    return float(np.clip(tau, 1.0, n))


def prior_weight(level: float, sigma: np.ndarray) -> np.ndarray:
    """The weight of a prior sample of standard deviation ``sigma`` (m per coordinate) against
    a position error of weight 1 that stands for ``level`` m (the fit's scaled residual SD):
    ``level / sigma``, so that the prior adds its information ``1 / sigma^2`` to the model's
    (inverse-variance fusion); at most 1 (never more than a recorded sample), 0 where
    ``sigma`` is NaN."""
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(np.isfinite(sigma) & (sigma > 0), level / sigma, 0.0)
    return np.clip(w, 0.0, 1.0)


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
    samples as soft position errors (:func:`pca_prior`, weights :func:`prior_weight` at the
    first fit's scaled residual SD): the model's dynamics and the markers present decide
    where the PCA fill is unsure; ``ModelFill.pure`` keeps the first fit's values.

    Raises:
        InputError: the model's trajectory goes non-finite from the record's states; an
            unknown prior; ``prior="pca"`` without complete frames.
    """
    if prior is not None and prior not in PRIORS:
        raise InputError("--prior", f"expected {', '.join(PRIORS)}, got '{prior}'")
    positions, mask = plan.positions, plan.mask
    n_frames, n_markers, dim = positions.shape
    dt = plan.traj.dt
    gaps = plan.local()
    values = np.array(positions)
    if not gaps and not denoise:
        return ModelFill(values, [])
    guide = pca_prior(positions, mask, gaps) if prior == "pca" and gaps else None
    pure = np.array(positions) if guide is not None else None
    spans = [(0, n_frames)] if denoise else segments_of(gaps, n_frames, context)
    x_all, v_all = frame_states(positions, mask, dt)  # every marker is present somewhere
    genome = jnp.asarray(model.layout.initial())
    # the model's time starts at the recording's first frame: a window that starts later
    # starts from the phase tracked along the frames before it
    psi0 = None
    if phase.entrained(model.topology) and plan.window[0] > 0:
        first, cols = plan.window[0], list(plan.columns)
        ahead = plan.traj.positions[: first + 1][:, cols]
        mask_ahead = plan.traj.mask[: first + 1][:, cols]
        psi0 = fill_phases(model, genome, ahead, mask_ahead, dt, substeps)[-1]
    psi = fill_phases(model, genome, positions, mask, dt, substeps, psi0)
    signal_cols = [] if psi is None else list(model.topology.drive.read)
    before = np.zeros_like(mask)  # the frames of the segments already filled
    sigma = np.zeros((n_frames, n_markers))
    segments = []
    for a, b in spans:
        weight = continuity
        if weight is None:
            ratio = one_step_ratio(
                model,
                genome,
                positions[a:b],
                mask[a:b],
                dt,
                plan.window[0] + a,
                substeps,
                integrator,
                phases=None if psi is None else psi[a:b],
            )
            weight = continuity_weight(ratio)
        inside = [g.stop - g.start for g in gaps if a <= g.start and g.stop <= b]
        fit = functools.partial(
            _fit_segment,
            model,
            genome,
            positions[a:b],
            mask[a:b],
            (x_all[a:b], v_all[a:b]),
            dt,
            plan.window[0] + a,
            horizon,
            substeps,
            integrator,
            max_steps,
            weight / CONTINUITY_WEIGHT,
            longest=max(inside, default=b - a),
            phases=None if psi is None else psi[a:b],
        )
        xs, sd, z, solved = fit()
        if psi is not None and not mask[a:b][:, signal_cols].all():
            # the signal's own gap: the phase tracked along the model's fill of it, refitted
            # until the two agree
            seen = mask | before
            seen[a:b] = True
            for _ in range(PHASE_ROUNDS):
                values[a:b][~mask[a:b]] = xs[~mask[a:b]]
                moved = psi
                psi = fill_phases(model, genome, values, seen, dt, substeps, psi0)
                if np.abs(psi[a:b] - moved[a:b]).max() < PHASE_TOL:
                    break
                steps = solved.steps
                xs, sd, z, solved = fit(phases=psi[a:b], start=z)
                solved = dataclasses.replace(solved, steps=steps + solved.steps)
            before[a:b] = True
        # the note on the model's continuity defects speaks of the model's own fit: a prior's
        # steady pull correlates the defects even of a true model
        model_tau = solved.tau
        prior_w = float("nan")
        if guide is not None:
            pure[a:b] = xs
            w = prior_weight(solved.level, guide[1][a:b])
            w_step = prior_weight(solved.level, guide[2][a:b])
            if np.any(w > 0):
                steps = solved.steps
                xs, sd, z, solved = fit(guide=(guide[0][a:b], w, w_step), start=z)
                solved = dataclasses.replace(solved, steps=steps + solved.steps)
                prior_w = float(np.median(w[w > 0]))
        seg = Segment(
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
        segments.append(seg)
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


class _Programs:
    """A segment's compiled functions, with its data (start frames, targets, weights, as
    :class:`.shooting.ShootingWindows` holds them, and the continuity weight's link) as
    arguments: compiled once per shape, not once per gap."""

    def __init__(self, model: Model, horizon: int, dt: float, substeps: int, integrator: str):
        self.model, self.horizon, self.dt = model, horizon, dt

        def windows(starts, target, weight, link, psi):
            k = target.shape[0]
            link_ = jnp.full(k - 1, link)
            segments = ((0, k, 0),)
            return ShootingWindows(
                starts, target, weight, dt, link=link_, segments=segments, phases=psi
            )

        def split(z, target):
            half = z.shape[1] // 2
            shape = target.shape[0], target.shape[2], target.shape[3]
            return z[:, :half].reshape(shape), z[:, half:].reshape(shape)

        def residual(z, genome, starts, target, weight, link, psi):
            w = windows(starts, target, weight, link, psi)
            res, _ = make_shooting(model, w, substeps, integrator)
            return jnp.concatenate([r.ravel() for r in res(genome, split(z, target))])

        def normal(z, genome, starts, target, weight, link, psi):
            w = windows(starts, target, weight, link, psi)
            build = make_normal(model, w, substeps, integrator, lambda u: genome + 0.0 * u[0])
            return build(jnp.zeros(1), z)

        def window_positions(z, genome, starts, target, psi):
            """Positions [K, H + 1, M D] of every window and their Jacobians [.., n]."""
            params = model.layout.decode(genome)
            n_particles, dim = target.shape[2], target.shape[3]
            half = n_particles * dim

            def run(s, t, *psi0):
                x, v = s[:half].reshape(n_particles, dim), s[half:].reshape(n_particles, dim)
                xs = rollout_states(
                    params, model.topology, x, v, dt, horizon, substeps, integrator, t, *psi0
                )[0]
                return jnp.concatenate([x[None], xs]).reshape(horizon + 1, -1)

            t0 = starts * dt
            extra = () if psi is None else (psi,)
            jac = jax.vmap(jax.jacfwd(run))(z, t0, *extra)
            return jax.vmap(run)(z, t0, *extra), jac

        self.residual = jax.jit(residual)
        self.normal = jax.jit(normal)
        self.positions = jax.jit(window_positions)


@functools.lru_cache(maxsize=4)
def _programs(model, horizon, dt, substeps, integrator) -> _Programs:
    return _Programs(model, horizon, dt, substeps, integrator)


def _fit_segment(
    model,
    genome,
    positions,
    mask,
    states,
    dt,
    first,
    horizon,
    substeps,
    integrator,
    max_steps,
    link=1.0,
    longest=1,
    guide=None,
    start=None,
    phases=None,
):
    """(positions [S, M, D], their uncertainties [S, M] (the standard errors scaled by the
    residuals, :func:`error_scale`; ``longest`` the segment's longest gap in frames), the
    solution's window states, a :class:`_Solved`). ``guide``: (targets [S, M, D], weights
    [S, M]) of a prior on missing samples (weight 0: none), fitted as soft position errors;
    ``start``: the window states to start from (default: the record's ``states``);
    ``phases`` [S]: an entrained drive's phase at every frame (:func:`fill_phases`)."""
    n_frames, n_markers, dim = positions.shape
    frame_weight = mask.astype(np.float64)
    observed = positions
    step_prior = None
    if guide is not None:
        g_target, g_weight, g_step = guide
        use = ~mask & (g_weight > 0)
        frame_weight = np.where(use, g_weight, frame_weight)
        observed = np.where(use[..., None], g_target, positions)
        if horizon == 1 and np.any(g_step > 0):  # every frame's state a variable
            step_prior = (np.diff(g_target, axis=0), g_step[:-1])
    local = shooting_windows(observed, frame_weight > 0, dt, horizon)
    k, h = len(local.starts), local.horizon
    frames = np.minimum(local.starts[:, None] + np.arange(h + 1)[None, :], n_frames - 1)
    weight = local.weight * frame_weight[frames]
    present = (local.weight > 0) & mask[frames]  # [K, H + 1, M]: the recorded samples
    programs = _programs(model, h, dt, substeps, integrator)
    # frames of the recording: time-dependent forces see its time
    data = (
        jnp.asarray(local.starts + first, jnp.float64),
        jnp.asarray(local.target),
        jnp.asarray(weight),
        jnp.asarray(float(link), jnp.float64),
        None if phases is None else jnp.asarray(np.asarray(phases)[local.starts]),
    )

    def flat(z):
        r = programs.residual(z, genome, *data)
        if step_prior is None:
            return r
        return jnp.concatenate([r, _step_residuals(z, *steps_data)])

    def linearize(z, _):
        system = programs.normal(z, genome, *data)
        if step_prior is not None:
            system = _with_steps(system, z, *steps_data)
        return system, system.grad_s

    def scale(system):
        return jnp.max(jnp.abs(jnp.diagonal(system.diag, axis1=1, axis2=2)))

    steps_data = None
    if step_prior is not None:
        # windows k, k + 1 start at frames k, k + 1 (horizon 1); the last frame is no start
        delta, w_step = step_prior[0][: k - 1], step_prior[1][: k - 1]
        steps_data = (jnp.asarray(np.nan_to_num(delta)), jnp.asarray(w_step))
    if start is None:
        x0, v0 = start_states(local, [states])
        z0 = jnp.concatenate([jnp.asarray(x0).reshape(k, -1), jnp.asarray(v0).reshape(k, -1)], 1)
    else:
        z0 = jnp.asarray(start)
    r0 = np.asarray(flat(z0))
    if not np.all(np.isfinite(r0)):
        raise InputError(
            "--method model",
            f"the model's trajectory goes non-finite from the record's states around frames "
            f"{first}:{first + n_frames}; try a shorter --horizon",
        )
    z, steps, message = levenberg_marquardt(
        flat,
        linearize,
        _LapackStep() if LAPACK else _states_step_jit,
        z0,
        max_steps,
        RTOL,
        ATOL,
        scale=scale,
        diagonal=_states_diagonal if MARQUARDT else None,
        damping=DAMPING,
    )
    pos, jac = (np.asarray(a) for a in programs.positions(z, genome, data[0], data[1], data[4]))
    kk = np.minimum(np.arange(n_frames) // h, k - 1)
    jj = np.arange(n_frames) - kk * h
    xs = pos[kk, jj].reshape(n_frames, n_markers, dim)
    r = np.asarray(flat(z))
    n_measured = k * (h + 1) * n_markers * dim
    measured = r[:n_measured].reshape(k, h + 1, n_markers, dim)
    recorded = int(present.sum())
    rms_mm = float(np.sqrt(np.sum(measured[present] ** 2) / max(1, recorded))) * 1000.0
    # the standard errors of the fitted positions: sigma^2 G T^-1 G^T
    terms = int((weight > 0).sum()) + (0 if steps_data is None else int((w_step > 0).sum()))
    variance = float(np.sum(r**2)) / max(1, terms * dim - z.shape[1])
    defects = r[n_measured : n_measured + (k - 1) * n_markers * dim]
    tau = defect_correlation(defects.reshape(k - 1, -1), longest) if k > 2 else 1.0
    noise = noise_estimate(positions, mask)
    factor = error_scale(np.sqrt(variance), noise, tau)
    if variance == 0.0 and np.isfinite(noise):  # an exact fit: the noise estimate's SD
        variance = noise**2
    system = programs.normal(z, genome, *data)
    if step_prior is not None:
        system = _with_steps(system, z, *steps_data)
    diag = np.asarray(system.diag)
    jitter = 1e-12 * float(np.max(np.abs(np.diagonal(diag, axis1=1, axis2=2))))
    cov = inverse_diagonal_blocks(diag + jitter * np.eye(diag.shape[1]), np.asarray(system.off))
    g = jac[kk, jj]  # [S, M D, n]
    var = np.einsum("smn,snp,smp->sm", g, cov[kk], g)  # per coordinate
    sd = np.sqrt(np.maximum(variance * var.reshape(n_frames, n_markers, dim).sum(-1), 0.0))
    level = factor * float(np.sqrt(variance))
    return xs, factor * sd, z, _Solved(steps, message, rms_mm, factor, tau, level)


@jax.jit
def _step_residuals(z, delta, w_step):
    """The step prior's residuals ``w (X_k+1 - X_k - delta_k)`` [K - 1, M, D] (flattened) of
    window states z [K, n] (horizon 1: window k starts at frame k)."""
    n_markers, dim = w_step.shape[1], delta.shape[2]
    x = z[:, : n_markers * dim].reshape(len(z), n_markers, dim)
    return (w_step[..., None] * (x[1:] - x[:-1] - delta)).ravel()


@jax.jit
def _with_steps(system, z, delta, w_step):
    """The normal equations with the step prior's terms added: each residual ``w (X_k+1 -
    X_k - delta_k)`` adds ``w^2`` to both frames' position diagonals, ``-w^2`` to their
    coupling, and ``-+ w r`` to their gradients."""
    n = system.diag.shape[1]
    dim = delta.shape[2]
    k = z.shape[0]
    w2 = jnp.repeat(w_step**2, dim, axis=1)  # [K - 1, M D]
    w2 = jnp.concatenate([w2, jnp.zeros((k - 1, n - w2.shape[1]))], axis=1)  # no velocity
    r = _step_residuals(z, delta, w_step).reshape(k - 1, -1)
    wr = jnp.repeat(w_step, dim, axis=1) * r
    wr = jnp.concatenate([wr, jnp.zeros((k - 1, n - wr.shape[1]))], axis=1)
    pad = jnp.zeros((1, n))
    d = jnp.concatenate([w2, pad]) + jnp.concatenate([pad, w2])
    g = jnp.concatenate([-wr, pad]) + jnp.concatenate([pad, wr])
    eye = jnp.eye(n)
    return system._replace(
        diag=system.diag + d[:, :, None] * eye,
        off=system.off - w2[:, :, None] * eye,
        grad_s=system.grad_s + g,
    )


@dataclass(frozen=True)
class _Solved:
    steps: int
    message: str
    rms_mm: float
    scale: float
    tau: float
    level: float  # m: what a position error of weight 1 stands for (the scaled residual SD)
