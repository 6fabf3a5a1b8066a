"""Multiple shooting's normal equations, by window, solved with the window states eliminated.

Window k's residuals r_k (its position errors, then its continuity defect with window k + 1)
depend on the parameters u, its own start state s_k = (X_k, V_k) and, through the defect
only and linearly, on the next start state: ``d r_k / d s_k+1 = -c_k diag(1, dt)`` with
``c_k = CONTINUITY_WEIGHT * link_k``. So J^T J is block-tridiagonal in the states with a
dense border for the parameters (the arrow of bundle adjustment and of Bock's multiple
shooting)::

    [ T    Y ] [ds]     [g_s]
    [ Y^T  P ] [du] = - [g_u]

Each window's Jacobian blocks are computed on their own (forward mode over its n + p
variables, windows mapped in batches), folded into their normal-equation blocks at once and
dropped: memory is linear in the number of windows. ``T`` is factored by the block
Cholesky recursion over the windows (the Riccati / block-Thomas recursion of
multiple-shooting codes), the states are eliminated by the Schur complement
``P - Y^T T^-1 Y`` (the parameters' own, marginal information) and only a dense system of
the parameters' size is solved.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import solve_triangular

from ...model.model import Model
from ...physics.integrate import rollout_states
from ..costs.shooting import CONTINUITY_WEIGHT, ShootingWindows, window_phases

BATCH_BYTES = 2**27  # Jacobian blocks computed at once, at most (windows are batched to fit)
LANES = 1024  # tangents (windows x unknowns per window) propagated at once, at most


class Normal(NamedTuple):
    """J^T J and J^T r of the shooting residuals, by block (n = 2 P D state coordinates)."""

    diag: jax.Array  # [K, n, n] T_kk
    off: jax.Array  # [K - 1, n, n] T_k,k+1
    cross: jax.Array  # [K, n, p] Y_k
    params: jax.Array  # [p, p] P
    grad_s: jax.Array  # [K, n]
    grad_u: jax.Array  # [p]


def make_normal(
    model: Model,
    windows: ShootingWindows,
    substeps: int,
    method: str,
    to_genome,
    unroll: bool = False,
):
    """``(u, S) -> Normal`` at parameters u (search space of ``to_genome``) and window
    states S [K, n] (each row: the window's start positions then velocities, flattened).
    ``unroll``: the substeps written out (:func:`~activebonds.physics.integrate.advance`)."""
    topo, layout = model.topology, model.layout
    dt, h = windows.dt, windows.horizon
    n_windows = len(windows.starts)
    n_particles, dim = windows.target.shape[2], windows.target.shape[3]
    half = n_particles * dim
    target = jnp.asarray(windows.target.reshape(n_windows, h + 1, -1))
    weight = jnp.asarray(np.repeat(windows.weight, dim, axis=-1).reshape(n_windows, -1))
    t0 = jnp.asarray(windows.times)
    # the last window: no defect (a traced link too: the fill passes its weight as an
    # argument); NumPy where it is data (no eager program compiled for a constant)
    xp = jnp if isinstance(windows.link, jax.Array) else np
    link = xp.concatenate([xp.asarray(windows.link), xp.zeros(1)])
    c = CONTINUITY_WEIGHT * link
    scale = np.concatenate([np.ones(half), np.full(half, dt)])  # of a state's defect

    phases = window_phases(model, windows, substeps)

    def window(u, s, t, tgt, wt, *k):
        params = layout.decode(to_genome(u))
        x, v = s[:half].reshape(n_particles, dim), s[half:].reshape(n_particles, dim)
        psi = () if phases is None else (phases(params)[k[0]],)  # tracked along the record
        xs, vs = rollout_states(
            params, topo, x, v, dt, h, substeps, method, t, *psi, unroll=unroll
        )[:2]
        pos = jnp.concatenate([x[None], xs]).reshape(h + 1, -1)
        measured = jnp.where(wt > 0, wt * (pos - tgt).ravel(), 0.0)
        return measured, jnp.concatenate([xs[-1].ravel(), vs[-1].ravel()])

    blocks = _window_blocks(window, scale)

    def normal(u, states):
        n, p = states.shape[1], u.shape[0]
        rows = target.shape[1] * target.shape[2] + n
        # windows mapped at once: few where each carries many tangents (a 41-marker body's
        # 660 run 2-3 times faster one window at a time than vmapped by 3 or 7)
        by_lanes = max(1, LANES // (n + p))
        batch, padded = _batches(n_windows, min(by_lanes, BATCH_BYTES // (8 * rows * (n + p) * 2)))
        nxt = jnp.concatenate([states[1:], jnp.zeros((1, n))])
        us = jnp.broadcast_to(u, (n_windows, p))
        ks = () if phases is None else (jnp.arange(n_windows),)
        inputs = (us, states, nxt, t0, target, weight, c, *ks)
        if padded > n_windows:  # copies of the last window, dropped below
            inputs = jax.tree.map(lambda a: _pad_rows(a, padded - n_windows), inputs)
        out = jax.lax.map(blocks, inputs, batch_size=batch)
        tkk, tk1, ykk, yk1, pkk, gkk, gk1, guk, dk1 = (a[:n_windows] for a in out)

        def shift(a):  # window k's contribution to window k + 1
            return jnp.concatenate([jnp.zeros_like(a[:1]), a[:-1]])

        eye = jnp.eye(n)
        return Normal(
            diag=tkk + shift(dk1)[:, :, None] * eye,
            off=tk1[:-1],
            cross=ykk + shift(yk1),
            params=pkk.sum(0),
            grad_s=gkk + shift(gk1),
            grad_u=guk.sum(0),
        )

    return normal


def _window_blocks(window, scale):
    """``args -> blocks``: window k's contributions to the normal equations (its diagonal
    block and the one to window k + 1, the cross terms with the parameters, the gradients,
    each with its continuity defect's part), from ``window`` (``(u, s, t, target, weight,
    *k) -> (measured residual, end state)``) and its Jacobian in u and s; ``scale``: of a
    state's defect."""
    jac = jax.jacfwd(window, argnums=(0, 1))

    def blocks(args):
        u, s, s_next, t, tgt, wt, ck, *k = args  # k: the window's index (entrained drive)
        rm, end = window(u, s, t, tgt, wt, *k)
        (bm, am), (be, ae) = jac(u, s, t, tgt, wt, *k)
        rg = ck * scale * (end - s_next)
        gs = ck * scale[:, None] * ae  # d defect / d s_k
        gu = ck * scale[:, None] * be  # d defect / d u
        return (
            am.T @ am + gs.T @ gs,
            -ck * gs.T * scale[None, :],  # T_k,k+1 = G_s^T (-c_k diag(scale))
            am.T @ bm + gs.T @ gu,
            -ck * scale[:, None] * gu,  # the defect's part of Y_k+1
            bm.T @ bm + gu.T @ gu,
            am.T @ rm + gs.T @ rg,
            -ck * scale * rg,  # its part of g_s,k+1
            bm.T @ rm + gu.T @ rg,
            ck**2 * scale**2,  # its part of diag(T_k+1,k+1)
        )

    return blocks


def _batches(n_windows: int, most: int) -> tuple[int, int]:
    """(batch, padded): windows mapped at once, at most ``most``, and the number of windows
    padded to a multiple of it. Batches of equal size: ``lax.map`` traces and compiles a
    remainder that is not a whole batch as a second program (the normal equations' trace and
    compilation twice over)."""
    n_batches = -(-n_windows // max(1, min(n_windows, most)))
    batch = -(-n_windows // n_batches)
    return batch, batch * n_batches


def _pad_rows(a, extra: int):
    """``a`` with its last row repeated ``extra`` times."""
    return jnp.concatenate([a, jnp.repeat(a[-1:], extra, axis=0)])


def block_tridiagonal_solve(diag, off, rhs):
    """Solve T Z = rhs for a symmetric positive definite block-tridiagonal T (``diag`` [K, n,
    n], ``off`` [K - 1, n, n] = T_k,k+1) and rhs [K, n, r], by the block Cholesky recursion
    (T = L L^T, L block-bidiagonal): forward over the windows, then back."""
    n = diag.shape[1]
    upper = jnp.concatenate([jnp.zeros((1, n, n)), off])  # upper[k] = T_k-1,k

    def forward(carry, inputs):
        l_prev, z_prev = carry
        d, e, r = inputs
        sub = solve_triangular(l_prev, e, lower=True).T  # L_k,k-1 = T_k,k-1 L_k-1^-T
        lk = jnp.linalg.cholesky(d - sub @ sub.T)
        z = solve_triangular(lk, r - sub @ z_prev, lower=True)
        return (lk, z), (lk, sub, z)

    start = (jnp.eye(n), jnp.zeros(rhs.shape[1:]))
    _, (chol, sub, z) = jax.lax.scan(forward, start, (diag, upper, rhs))
    sub_next = jnp.concatenate([sub[1:], jnp.zeros((1, n, n))])  # L_k+1,k

    def backward(x_next, inputs):
        lk, s, zk = inputs
        x = solve_triangular(lk.T, zk - s.T @ x_next, lower=False)
        return x, x

    _, x = jax.lax.scan(backward, jnp.zeros(rhs.shape[1:]), (chol, sub_next, z), reverse=True)
    return x


def eliminate(normal: Normal, damping, state_damping=None):
    """The Schur complement of the states and its right-hand side: (S + damping I, b, Z)
    with ``Z = T_damped^-1 [Y, g_s]``, so that ``(S + damping I) du = b`` and
    ``ds = -Z_g - Z_Y du``; ``state_damping`` (default ``damping``) is added to T's
    diagonal."""
    n, p = normal.diag.shape[1], normal.params.shape[0]
    state_damping = damping if state_damping is None else state_damping
    # scalars (times I) or vectors ([K, n] and [p]: a diagonal of their own)
    t = normal.diag + jnp.asarray(state_damping)[..., None] * jnp.eye(n)
    z = block_tridiagonal_solve(
        t, normal.off, jnp.concatenate([normal.cross, normal.grad_s[..., None]], axis=-1)
    )
    zy, zg = z[..., :p], z[..., p]
    damp_u = jnp.asarray(damping)[..., None] * jnp.eye(p)
    reduced = normal.params + damp_u - jnp.einsum("knp,knq->pq", normal.cross, zy)
    b = -normal.grad_u + jnp.einsum("knp,kn->p", normal.cross, zg)
    return reduced, b, (zy, zg)


FLOOR = 1e-9  # of the largest diagonal entry: the least a variable's damping is scaled by


@jax.jit
def marquardt_diagonal(normal: Normal):
    """J^T J's diagonal as (du [p], dS [K, n]), floored at :data:`FLOOR` of its largest entry
    (a variable the data do not see is still damped): Marquardt's scaling of the damping."""
    return floored((jnp.diagonal(normal.params), jnp.diagonal(normal.diag, axis1=1, axis2=2)))


def floored(diagonal):
    """A diagonal (an array or a tuple of arrays) floored at :data:`FLOOR` of its largest
    entry."""
    floor = FLOOR * jnp.max(jnp.stack([jnp.max(d) for d in jax.tree.leaves(diagonal)]))
    return jax.tree.map(lambda d: jnp.maximum(d, floor), diagonal)


@jax.jit
def damped_step(normal: Normal, damping):
    """The Levenberg-Marquardt step (du, dS) solving (J^T J + D) d = -J^T r, D = damping I
    (a number) or diag(damping) (a pair ([p], [K, n]) like the step)."""
    if isinstance(damping, tuple | list):
        reduced, b, (zy, zg) = eliminate(normal, damping[0], damping[1])
    else:
        reduced, b, (zy, zg) = eliminate(normal, damping)
    du = jnp.linalg.solve(reduced, b)
    return du, -zg - jnp.einsum("knp,p->kn", zy, du)


@jax.jit
def marginal_information(normal: Normal):
    """The parameters' information with the states eliminated (the Schur complement at no
    damping): its inverse is their Gauss-Newton covariance, the states being nuisance."""
    scale = jnp.max(jnp.abs(jnp.diagonal(normal.diag, axis1=1, axis2=2)))
    # a jitter of T alone keeps its Cholesky defined where a state is unseen
    reduced, _, _ = eliminate(normal, 0.0, 1e-16 * scale)
    return 0.5 * (reduced + reduced.T)


@jax.jit
def curvature(normal: Normal, d):
    """d^T (J^T J) d for a step d = (du [p], dS [K, n]), from the blocks (no dense matrix):
    the prediction of a step that is not the damped solve's (projected onto bounds)."""
    du, ds = d
    states = jnp.einsum("ki,kij,kj->", ds, normal.diag, ds)
    states += 2.0 * jnp.einsum("ki,kij,kj->", ds[:-1], normal.off, ds[1:])
    cross = 2.0 * jnp.einsum("ki,kip,p->", ds, normal.cross, du)
    return states + cross + du @ (normal.params @ du)
