"""The fitted model's fastest oscillation against its integrator's step.

Semi-implicit Euler and velocity Verlet share one dispersion relation for a harmonic
oscillator of frequency omega at a step h: the discrete motion turns by theta a step where
``2 sin(theta / 2) = omega h``. A fit at too coarse a step therefore finds the omega whose
discrete motion matches the recording's: where the recording turns by theta a step, the fitted
``omega = (2 / h) sin(theta / 2)``, below the true theta / h, and the stiffness (omega^2 times a
mass) low by ``(2 sin(theta / 2) / theta)^2 - 1`` (-8 % at theta = 1 rad, -14 % at 1.32). The
fit absorbs that bias into the parameters, with no symptom in its residuals or intervals.

:func:`fastest` linearises the model's forces at rest about recorded configurations (K =
-dF/dx at zero velocity, by automatic differentiation: every kind, a contact where it touches)
and takes the largest frequency of ``M^-1/2 K M^-1/2``; :func:`stiffness_bias` is the bias of
a stiffness at that frequency, :func:`substeps_for` the substeps that bring it within
:data:`TOLERANCE`. Dampers are not counted.
"""

from __future__ import annotations

import math

import numpy as np

TOLERANCE = 0.01  # a stiffness bias this small is left unsaid
MAX_SUBSTEPS = 64  # substeps suggested at most


def fastest(model, positions: np.ndarray) -> float:
    """The largest angular frequency (rad/s) of ``model``'s forces linearised at rest at each
    configuration of ``positions`` [F, P, D] (m), with its masses: the largest over the
    frames of sqrt(eig(M^-1/2 K M^-1/2)), K = -dF/dx at zero velocity (every kind's forces,
    through :func:`~activebonds.physics.forces.total_force`; a contact counts where it
    touches); 0 without stiffness."""
    import jax
    import jax.numpy as jnp

    from ...physics.forces import total_force

    params, top = model.params, model.topology
    x = np.asarray(positions, np.float64)
    _, p, d = x.shape

    @jax.jit
    def frequencies(xf):
        def force(flat):
            return total_force(params, top, flat.reshape(p, d), jnp.zeros((p, d))).ravel()

        k = -jax.jacfwd(force)(xf.ravel())
        scale = jnp.repeat(1.0 / jnp.sqrt(jnp.asarray(params.mass)), d)
        sym = scale[:, None] * k * scale[None, :]
        return jnp.linalg.eigvalsh(0.5 * (sym + sym.T))[-1]

    with jax.enable_x64(True):
        top_eig = max((float(frequencies(jnp.asarray(xf))) for xf in x), default=0.0)
    return float(math.sqrt(max(top_eig, 0.0)))


def stiffness_bias(omega: float, step: float) -> float | None:
    """The relative bias of a stiffness fitted at ``omega`` (rad/s) with integrator step
    ``step`` (s) on a recording of finer motion; None where ``omega step >= 2`` (the step at
    its stability limit: no recording's motion would give that fit)."""
    wh = omega * step
    if wh >= 2.0:
        return None
    if wh <= 0.0:
        return 0.0
    theta = 2.0 * math.asin(wh / 2.0)
    return (wh / theta) ** 2 - 1.0


def substeps_for(omega: float, dt: float, tolerance: float = TOLERANCE) -> int:
    """The fewest substeps a frame of ``dt`` (s) for which :func:`stiffness_bias` is within
    ``tolerance`` (at most :data:`MAX_SUBSTEPS`)."""
    for n in range(1, MAX_SUBSTEPS + 1):
        bias = stiffness_bias(omega, dt / n)
        if bias is not None and abs(bias) <= tolerance:
            return n
    return MAX_SUBSTEPS


def warning(omega: float, dt: float, substeps: int) -> str | None:
    """The bias in words where it exceeds :data:`TOLERANCE`, else None."""
    step = dt / max(1, int(substeps))
    bias = stiffness_bias(omega, step)
    if bias is not None and abs(bias) <= TOLERANCE:
        return None
    more = substeps_for(omega, dt)
    at = f"--substeps {substeps}"
    if bias is None:
        size = "at the step's stability limit, where no stiffness can be trusted"
    else:
        size = f"where a step of this integrator puts a stiffness {100 * bias:+.1f} % off"
    after = stiffness_bias(omega, dt / more)
    return (
        f"the fitted springs' fastest oscillation, {omega:.4g} rad/s, turns "
        f"{omega * step:.2f} rad in one integrator step at {at}, {size} (the fit absorbs it "
        f"into the parameters and their intervals do not show it); refit with --substeps "
        f"{more} ({100 * (after or 0.0):+.1f} %)"
    )
