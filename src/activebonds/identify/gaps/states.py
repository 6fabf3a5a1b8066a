"""The linear algebra of the fill's state solve: the damped Gauss-Newton step of the shooting
windows' states (block-tridiagonal, by JAX or by LAPACK), Marquardt's scaling of its damping,
the diagonal blocks of the inverse (the states' covariance), and the step prior's residuals and
normal-equation terms (:func:`.prior.pca_prior`'s steps from frame to frame)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..solvers.shooting_normal import block_tridiagonal_solve, floored


def states_step(system, damping):
    """The damped Gauss-Newton step of the states alone: (T + D) d = -g_s, D = damping I
    (a number) or diag(damping) ([K, n]: Marquardt's scaling)."""
    n = system.diag.shape[1]
    rhs = -system.grad_s[..., None]
    damp = jnp.asarray(damping)[..., None] * jnp.eye(n)
    return block_tridiagonal_solve(system.diag + damp, system.off, rhs)[..., 0]


states_step_jit = jax.jit(states_step)


class LapackStep:
    """:func:`states_step` by LAPACK (SciPy), the system copied out of JAX once per
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
def states_diagonal(system):
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


@jax.jit
def step_residuals(z, delta, w_step):
    """The step prior's residuals ``w (X_k+1 - X_k - delta_k)`` [K - 1, M, D] (flattened) of
    window states z [K, n] (horizon 1: window k starts at frame k)."""
    n_markers, dim = w_step.shape[1], delta.shape[2]
    x = z[:, : n_markers * dim].reshape(len(z), n_markers, dim)
    return (w_step[..., None] * (x[1:] - x[:-1] - delta)).ravel()


@jax.jit
def with_steps(system, z, delta, w_step):
    """The normal equations with the step prior's terms added: each residual ``w (X_k+1 -
    X_k - delta_k)`` adds ``w^2`` to both frames' position diagonals, ``-w^2`` to their
    coupling, and ``-+ w r`` to their gradients."""
    n = system.diag.shape[1]
    dim = delta.shape[2]
    k = z.shape[0]
    w2 = jnp.repeat(w_step**2, dim, axis=1)  # [K - 1, M D]
    w2 = jnp.concatenate([w2, jnp.zeros((k - 1, n - w2.shape[1]))], axis=1)  # no velocity
    r = step_residuals(z, delta, w_step).reshape(k - 1, -1)
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
