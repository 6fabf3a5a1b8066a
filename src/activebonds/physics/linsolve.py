"""Small dense linear solves written in array operations, for the solves inside the
integrator's loops (the implicit kick's D x D systems, the start velocity's P D x P D Newton
steps).

``jnp.linalg.solve`` calls LAPACK on the CPU (``getrf``, ``trsm``), and jaxlib 0.10's LAPACK
kernels split a batch over XLA's intra-op thread pool and block their pool thread until the
pieces are done. Where the program runs two or more such calls at once (a vmapped solve
inside a loop, e.g. a Jacobian of the one-step cost with substeps and contacts), every pool
thread can be waiting so, the pieces never run, and the process hangs at 0 % CPU (seen on a
2-core machine; pinned to one core it does not hang). Solving here, in XLA's own
operations, involves no library call and no thread pool.

:func:`solve` is Gauss elimination with partial pivoting (LAPACK's ``getrf`` algorithm, a
loop over the columns), with its derivative by the same factors (``d x = A^-1 (d b - d A
x)``), so a forward-mode Jacobian over many directions costs one factorisation and a pair of
triangular solves per direction.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def _lu(a):
    """(LU [n, n], row order [n]) of ``a`` [n, n] with partial pivoting: ``a[order] = L U``,
    L unit lower triangular (below the diagonal of LU), U upper triangular. A loop over the
    columns, so the program's size does not grow with n (a 41-marker body's start velocity
    solves 123 unknowns)."""
    n = a.shape[-1]
    rows = jnp.arange(n)

    def column(k, carry):
        lu, order = carry
        p = jnp.argmax(jnp.where(rows >= k, jnp.abs(lu[:, k]), -1.0))
        swap = rows.at[k].set(p).at[p].set(k)
        lu, order = lu[swap], order[swap]
        below = rows > k
        factor = jnp.where(below, lu[:, k] / lu[k, k], 0.0)
        lu = lu - factor[:, None] * jnp.where(below, lu[k], 0.0)[None, :]
        lu = lu.at[:, k].set(jnp.where(below, factor, lu[:, k]))
        return lu, order

    return jax.lax.fori_loop(0, n, column, (a, rows))


def _lu_solve(lu, order, b):
    """x with ``a x = b`` from :func:`_lu`'s factors of ``a``; b [n]."""
    n = lu.shape[-1]
    lower, upper = jnp.tril(lu, -1), jnp.triu(lu, 1)

    def forward(k, y):  # L y = b[order], column by column
        return y - lower[:, k] * y[k]

    def backward(j, y):  # U x = y, from the last column
        k = n - 1 - j
        y = y.at[k].set(y[k] / lu[k, k])
        return y - upper[:, k] * y[k]

    y = jax.lax.fori_loop(0, n - 1, forward, b[order])
    return jax.lax.fori_loop(0, n, backward, y)


@jax.custom_jvp
def solve(a, b):
    """x with ``a x = b``: a [n, n], b [n] (vmap for batches). NaN or inf where ``a`` is
    singular, as LAPACK's."""
    return _lu_solve(*_lu(a), b)


@solve.defjvp
def _solve_jvp(primals, tangents):
    a, b = primals
    da, db = tangents
    lu, order = _lu(a)
    x = _lu_solve(lu, order, b)
    return x, _lu_solve(lu, order, db - da @ x)
