"""One stretch of the model's fill: its shooting windows' states solved by Levenberg-Marquardt
with the model's parameters fixed, the missing samples masked (a prior's samples, if any, as
soft position errors), and the fitted positions' uncertainties (:mod:`.fill` describes both).
The compiled programs are kept per shape (:func:`_programs`): compiled once, not once per gap."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ...errors import InputError
from ...model.model import Model
from ...physics.integrate import rollout_states
from ..costs.shooting import ShootingWindows, make_shooting, shooting_windows, start_states
from ..solvers.lm import levenberg_marquardt
from ..solvers.shooting_normal import make_normal
from .states import (
    LapackStep,
    inverse_diagonal_blocks,
    states_diagonal,
    states_step_jit,
    step_residuals,
    with_steps,
)
from .uncertainty import defect_correlation, error_scale, noise_estimate

RTOL, ATOL = 1e-10, 1e-12
MARQUARDT = True
DAMPING = 1e-3
LAPACK = True


@dataclass(frozen=True)
class Solved:
    """How one stretch's fit ended."""

    steps: int
    message: str
    rms_mm: float
    scale: float
    tau: float
    level: float  # m: what a position error of weight 1 stands for (the scaled residual SD)


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


def fit_segment(
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
    residuals, :func:`.uncertainty.error_scale`; ``longest`` the segment's longest gap in
    frames), the solution's window states, a :class:`Solved`). ``guide``: (targets [S, M, D],
    weights [S, M]) of a prior on missing samples (weight 0: none), fitted as soft position
    errors; ``start``: the window states to start from (default: the record's ``states``);
    ``phases`` [S]: an entrained drive's phase at every frame
    (:func:`.dynamics.fill_phases`)."""
    n_frames = len(positions)
    frame_weight, observed, step_prior = _observations(positions, mask, guide, horizon)
    local = shooting_windows(observed, frame_weight > 0, dt, horizon)
    k, h = len(local.starts), local.horizon
    frames = np.minimum(local.starts[:, None] + np.arange(h + 1)[None, :], n_frames - 1)
    weight = local.weight * frame_weight[frames]
    programs = _programs(model, h, dt, substeps, integrator)
    # frames of the recording: time-dependent forces see its time
    data = (
        jnp.asarray(local.starts + first, jnp.float64),
        jnp.asarray(local.target),
        jnp.asarray(weight),
        jnp.asarray(float(link), jnp.float64),
        None if phases is None else jnp.asarray(np.asarray(phases)[local.starts]),
    )
    steps_data = None
    if step_prior is not None:
        # windows k, k + 1 start at frames k, k + 1 (horizon 1); the last frame is no start
        delta, w_step = step_prior[0][: k - 1], step_prior[1][: k - 1]
        steps_data = (jnp.asarray(np.nan_to_num(delta)), jnp.asarray(w_step))
    system = functools.partial(_system, programs, genome, data, steps_data)

    def flat(z):
        r = programs.residual(z, genome, *data)
        if steps_data is None:
            return r
        return jnp.concatenate([r, step_residuals(z, *steps_data)])

    if start is None:
        x0, v0 = start_states(local, [states])
        z0 = jnp.concatenate([jnp.asarray(x0).reshape(k, -1), jnp.asarray(v0).reshape(k, -1)], 1)
    else:
        z0 = jnp.asarray(start)
    if not np.all(np.isfinite(np.asarray(flat(z0)))):
        raise InputError(
            "--method model",
            f"the model's trajectory goes non-finite from the record's states around frames "
            f"{first}:{first + n_frames}; try a shorter --horizon",
        )
    z, steps, message = _solve(flat, system, z0, max_steps)
    pos, jac = (np.asarray(a) for a in programs.positions(z, genome, data[0], data[1], data[4]))
    present = (local.weight > 0) & mask[frames]  # [K, H + 1, M]: the recorded samples
    terms = int((weight > 0).sum()) + (0 if steps_data is None else int((w_step > 0).sum()))
    fitted = _Fitted(positions, mask, pos, jac, np.asarray(flat(z)), present, terms, longest)
    xs, sd, solved = fitted.solution(system(z), z.shape[1], steps, message)
    return xs, sd, z, solved


def _solve(flat, system, z0, max_steps):
    """(the window states, the steps taken, how the solve ended): Levenberg-Marquardt on the
    residuals ``flat`` from ``z0``, each step from the normal equations ``system(z)``."""

    def linearize(z, _):
        built = system(z)
        return built, built.grad_s

    def scale(built):
        return jnp.max(jnp.abs(jnp.diagonal(built.diag, axis1=1, axis2=2)))

    return levenberg_marquardt(
        flat,
        linearize,
        LapackStep() if LAPACK else states_step_jit,
        z0,
        max_steps,
        RTOL,
        ATOL,
        scale=scale,
        diagonal=states_diagonal if MARQUARDT else None,
        damping=DAMPING,
    )


def _observations(positions, mask, guide, horizon):
    """(the weight of every sample [S, M], the positions observed [S, M, D], the step prior
    (its steps [S - 1, M, D] and weights [S - 1, M]) or None): the recorded samples, and a
    prior's where a sample is missing and the prior weighs it."""
    frame_weight = mask.astype(np.float64)
    if guide is None:
        return frame_weight, positions, None
    g_target, g_weight, g_step = guide
    use = ~mask & (g_weight > 0)
    frame_weight = np.where(use, g_weight, frame_weight)
    observed = np.where(use[..., None], g_target, positions)
    step_prior = None
    if horizon == 1 and np.any(g_step > 0):  # every frame's state a variable
        step_prior = (np.diff(g_target, axis=0), g_step[:-1])
    return frame_weight, observed, step_prior


def _system(programs, genome, data, steps_data, z):
    """The normal equations at window states ``z``, with the step prior's terms if any."""
    system = programs.normal(z, genome, *data)
    if steps_data is not None:
        system = with_steps(system, z, *steps_data)
    return system


@dataclass(frozen=True)
class _Fitted:
    """A stretch at its solution: the record (``positions``, ``mask`` [S, M]), every window's
    positions ``pos`` [K, H + 1, M D] and their Jacobians ``jac``, the residuals ``r``, the
    recorded samples ``present`` [K, H + 1, M], the number of weighed ``terms`` and the
    stretch's longest gap in frames."""

    positions: np.ndarray
    mask: np.ndarray
    pos: np.ndarray
    jac: np.ndarray
    r: np.ndarray
    present: np.ndarray
    terms: int
    longest: int

    def solution(self, system, unknowns: int, steps: int, message: str):
        """(positions [S, M, D], their scaled standard errors [S, M], a :class:`Solved`)."""
        n_frames, n_markers, dim = self.positions.shape
        k, h = self.pos.shape[0], self.pos.shape[1] - 1
        kk = np.minimum(np.arange(n_frames) // h, k - 1)
        jj = np.arange(n_frames) - kk * h
        xs = self.pos[kk, jj].reshape(n_frames, n_markers, dim)
        r = self.r
        n_measured = k * (h + 1) * n_markers * dim
        measured = r[:n_measured].reshape(k, h + 1, n_markers, dim)
        recorded = int(self.present.sum())
        rms_mm = float(np.sqrt(np.sum(measured[self.present] ** 2) / max(1, recorded))) * 1000.0
        # the standard errors of the fitted positions: sigma^2 G T^-1 G^T
        variance = float(np.sum(r**2)) / max(1, self.terms * dim - unknowns)
        defects = r[n_measured : n_measured + (k - 1) * n_markers * dim]
        tau = defect_correlation(defects.reshape(k - 1, -1), self.longest) if k > 2 else 1.0
        noise = noise_estimate(self.positions, self.mask)
        factor = error_scale(np.sqrt(variance), noise, tau)
        if variance == 0.0 and np.isfinite(noise):  # an exact fit: the noise estimate's SD
            variance = noise**2
        diag = np.asarray(system.diag)
        jitter = 1e-12 * float(np.max(np.abs(np.diagonal(diag, axis1=1, axis2=2))))
        cov = inverse_diagonal_blocks(diag + jitter * np.eye(diag.shape[1]), np.asarray(system.off))
        g = self.jac[kk, jj]  # [S, M D, n]
        var = np.einsum("smn,snp,smp->sm", g, cov[kk], g)  # per coordinate
        sd = np.sqrt(np.maximum(variance * var.reshape(n_frames, n_markers, dim).sum(-1), 0.0))
        level = factor * float(np.sqrt(variance))
        return xs, factor * sd, Solved(steps, message, rms_mm, factor, tau, level)
