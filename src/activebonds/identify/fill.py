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
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from ..data.fill import FillPlan
from ..errors import InputError
from ..model.model import Model
from ..physics import phase
from ..physics.integrate import rollout_states
from ..runtime import float64
from .lm import levenberg_marquardt
from .shooting import (
    CONTINUITY_WEIGHT,
    ShootingWindows,
    frame_states,
    make_shooting,
    shooting_windows,
    start_states,
)
from .shooting_normal import block_tridiagonal_solve, make_normal

MAX_STEPS = 200
RATIO_FRAMES = 8  # frames ahead of the prediction that sets the continuity weight
HORIZON = 1  # frames per shooting window: every frame's state its own unknown
CONTINUITY = 0.3  # least weight of a continuity defect against a position error (metres each)
RTOL, ATOL = 1e-10, 1e-12
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
    tau: float = 1.0  # the continuity defects' integrated autocorrelation

    def record(self) -> dict:
        return {
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
    """The damped Gauss-Newton step of the states alone: (T + damping I) d = -g_s."""
    n = system.diag.shape[1]
    rhs = -system.grad_s[..., None]
    return block_tridiagonal_solve(system.diag + damping * jnp.eye(n), system.off, rhs)[..., 0]


_states_step_jit = jax.jit(_states_step)


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
    model: Model, genome, positions, mask, dt, first, substeps=1, integrator="euler"
) -> float:
    """How much of the motion's accelerations the model leaves unexplained: on the frames t of
    ``positions`` [S, M, D] where every marker is present at t - n, t and t + n
    (n = ``RATIO_FRAMES``), the RMS of ``x(t+n) - 2 x(t) + x(t-n) - (n dt)^2 F(x, v, t) / m``
    over the RMS of the second difference alone (zero force's), with v the central difference
    over 2 n frames; NaN without such frames. Over several frames the accelerations outgrow
    the marker noise, which a one-frame ratio would measure instead. (``substeps`` and
    ``integrator`` are the fill's; the ratio reads the forces alone.)"""
    from ..physics.forces import total_force

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

    def accel(x0, v0, time):
        return total_force(params, model.topology, x0, v0, time) / params.mass[:, None]

    a = np.asarray(jax.vmap(accel)(jnp.asarray(x), jnp.asarray(v), jnp.asarray((t + first) * dt)))
    second = nxt - 2.0 * x + prev
    e_model = float(np.sqrt(np.mean(np.square(second - (n * dt) ** 2 * a))))
    e_zero = float(np.sqrt(np.mean(np.square(second))))
    return e_model / e_zero if e_zero > 0.0 else float("nan")


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
) -> ModelFill:
    """The model's fill of the plan's gaps (see the module docstring).

    Raises:
        InputError: the model's trajectory goes non-finite from the record's states, or its
            drive is entrained (not supported here yet).
    """
    if phase.entrained(model.topology):
        raise InputError(
            "--method model",
            "a model with an entrained drive cannot fill gaps yet (its phase would be tracked "
            "along the gaps themselves); fill with a model without [drive] coupling",
        )
    positions, mask = plan.positions, plan.mask
    n_frames, n_markers, dim = positions.shape
    dt = plan.traj.dt
    gaps = plan.local()
    values = np.array(positions)
    if not gaps and not denoise:
        return ModelFill(values, [])
    spans = [(0, n_frames)] if denoise else segments_of(gaps, n_frames, context)
    x_all, v_all = frame_states(positions, mask, dt)  # every marker is present somewhere
    genome = jnp.asarray(model.layout.initial())
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
            )
            weight = continuity_weight(ratio)
        inside = [g.stop - g.start for g in gaps if a <= g.start and g.stop <= b]
        xs, sd, seg = _fit_segment(
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
        )
        steps, message, rms, scale, tau = seg
        seg = Segment(a, b, steps, message, rms, continuity=weight, scale=scale, tau=tau)
        segments.append(seg)
        values[a:b] = xs
        sigma[a:b] = sd
    if not denoise:
        # only the gaps are the model's: elsewhere the record stays as it was
        keep = mask.copy()
        values[keep] = positions[keep]
    return ModelFill(values, [sigma[g.start : g.stop, g.column] for g in gaps], segments)


class _Programs:
    """A segment's compiled functions, with its data (start frames, targets, weights, as
    :class:`.shooting.ShootingWindows` holds them) as arguments: compiled once per shape, not
    once per gap."""

    def __init__(
        self, model: Model, horizon: int, dt: float, substeps: int, integrator: str, link: float
    ):
        self.model, self.horizon, self.dt = model, horizon, dt

        def windows(starts, target, weight):
            k = target.shape[0]
            link_ = np.full(k - 1, link)
            return ShootingWindows(starts, target, weight, dt, link=link_, segments=((0, k, 0),))

        def split(z, target):
            half = z.shape[1] // 2
            shape = target.shape[0], target.shape[2], target.shape[3]
            return z[:, :half].reshape(shape), z[:, half:].reshape(shape)

        def residual(z, genome, starts, target, weight):
            res, _ = make_shooting(model, windows(starts, target, weight), substeps, integrator)
            return jnp.concatenate([r.ravel() for r in res(genome, split(z, target))])

        def normal(z, genome, starts, target, weight):
            w = windows(starts, target, weight)
            build = make_normal(model, w, substeps, integrator, lambda u: genome + 0.0 * u[0])
            return build(jnp.zeros(1), z)

        def window_positions(z, genome, starts, target):
            """Positions [K, H + 1, M D] of every window and their Jacobians [.., n]."""
            params = model.layout.decode(genome)
            n_particles, dim = target.shape[2], target.shape[3]
            half = n_particles * dim

            def run(s, t):
                x, v = s[:half].reshape(n_particles, dim), s[half:].reshape(n_particles, dim)
                xs, _ = rollout_states(
                    params, model.topology, x, v, dt, horizon, substeps, integrator, t
                )
                return jnp.concatenate([x[None], xs]).reshape(horizon + 1, -1)

            t0 = starts * dt
            return jax.vmap(run)(z, t0), jax.vmap(jax.jacfwd(run))(z, t0)

        self.residual = jax.jit(residual)
        self.normal = jax.jit(normal)
        self.positions = jax.jit(window_positions)


@functools.lru_cache(maxsize=4)
def _programs(model, horizon, dt, substeps, integrator, link=1.0) -> _Programs:
    return _Programs(model, horizon, dt, substeps, integrator, link)


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
):
    """(positions [S, M, D], their uncertainties [S, M] (the standard errors scaled by the
    residuals, :func:`error_scale`; ``longest`` the segment's longest gap in frames), (steps,
    message, RMS mm, scale, tau))."""
    n_frames, n_markers, dim = positions.shape
    local = shooting_windows(positions, mask, dt, horizon)
    x0, v0 = start_states(local, [states])
    k, h = len(local.starts), local.horizon
    programs = _programs(model, h, dt, substeps, integrator, float(link))
    # frames of the recording: time-dependent forces see its time
    data = (
        jnp.asarray(local.starts + first, jnp.float64),
        jnp.asarray(local.target),
        jnp.asarray(local.weight),
    )

    def flat(z):
        return programs.residual(z, genome, *data)

    def linearize(z, _):
        system = programs.normal(z, genome, *data)
        return system, system.grad_s

    def scale(system):
        return jnp.max(jnp.abs(jnp.diagonal(system.diag, axis1=1, axis2=2)))

    z0 = jnp.concatenate([jnp.asarray(x0).reshape(k, -1), jnp.asarray(v0).reshape(k, -1)], 1)
    r0 = np.asarray(flat(z0))
    if not np.all(np.isfinite(r0)):
        raise InputError(
            "--method model",
            f"the model's trajectory goes non-finite from the record's states around frames "
            f"{first}:{first + n_frames}; try a shorter --horizon",
        )
    z, steps, message = levenberg_marquardt(
        flat, linearize, _states_step_jit, z0, max_steps, RTOL, ATOL, scale=scale
    )
    pos, jac = (np.asarray(a) for a in programs.positions(z, genome, data[0], data[1]))
    frames = np.arange(n_frames)
    kk = np.minimum(frames // h, k - 1)
    jj = frames - kk * h
    xs = pos[kk, jj].reshape(n_frames, n_markers, dim)
    r = np.asarray(flat(z))
    terms = int(local.weight.sum())
    measured = r[: k * (h + 1) * n_markers * dim]
    rms_mm = float(np.sqrt(np.sum(measured**2) / max(1, terms))) * 1000.0
    # the standard errors of the fitted positions: sigma^2 G T^-1 G^T
    variance = float(np.sum(r**2)) / max(1, terms * dim - z.shape[1])
    defects = r[measured.size : measured.size + (k - 1) * n_markers * dim]
    tau = defect_correlation(defects.reshape(k - 1, -1), longest) if k > 2 else 1.0
    noise = noise_estimate(positions, mask)
    scale = error_scale(np.sqrt(variance), noise, tau)
    if variance == 0.0 and np.isfinite(noise):  # an exact fit: the noise estimate's SD
        variance = noise**2
    system = programs.normal(z, genome, *data)
    diag = np.asarray(system.diag)
    jitter = 1e-12 * float(np.max(np.abs(np.diagonal(diag, axis1=1, axis2=2))))
    cov = inverse_diagonal_blocks(diag + jitter * np.eye(diag.shape[1]), np.asarray(system.off))
    g = jac[kk, jj]  # [S, M D, n]
    var = np.einsum("smn,snp,smp->sm", g, cov[kk], g)  # per coordinate
    sd = np.sqrt(np.maximum(variance * var.reshape(n_frames, n_markers, dim).sum(-1), 0.0))
    return xs, scale * sd, (steps, message, rms_mm, scale, tau)
