"""Summing per-bond force rows into particles without a scatter-add.

Two forms, the same sums (a scatter-add vmapped over a population is slow on CPU):

* unrolled: the topology is static, so each particle's sum is written out as plain slices and
  adds. Fastest for small models, but its compile time grows with the number of terms
  (~0.03 s a particle);
* gathered: each particle's terms as one padded index table ``[P, K]`` (K the largest number
  of terms at a particle) into the signed rows, one gather and one sum. Its compile time does
  not grow with the model.

:func:`accumulate` picks the unrolled form up to :data:`UNROLL_TERMS` terms.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

UNROLL_TERMS = 64  # terms (bond ends) up to which the sums are unrolled


def accumulate(n: int, terms, form: str | None = None) -> jnp.ndarray:
    """Sum per-element force rows into particles: ``terms`` is a list of (index array,
    sign, rows [K, D]); returns [n, D]. ``form``: "unrolled", "gathered" or None (by size)."""
    count = sum(len(np.asarray(index)) for index, _, _ in terms)
    if form is None:
        form = "unrolled" if count <= UNROLL_TERMS else "gathered"
    if form == "unrolled":
        return _unrolled(n, terms)
    return _gathered(n, terms)


def _unrolled(n: int, terms) -> jnp.ndarray:
    dim = terms[0][2].shape[-1]
    dtype = terms[0][2].dtype
    per_particle = [[] for _ in range(n)]
    for index, sign, rows in terms:
        for k, p in enumerate(np.asarray(index)):
            per_particle[int(p)].append((sign, rows[k]))
    out = []
    for contributions in per_particle:
        total = jnp.zeros((dim,), dtype)
        for sign, row in contributions:
            total = total + row if sign > 0 else total - row
        out.append(total)
    return jnp.stack(out)


def gather_table(n: int, indices) -> tuple[np.ndarray, np.ndarray]:
    """For index arrays ``indices`` (one per term group, their rows numbered one after the
    other), the rows each particle sums: a table [n, K] of row numbers (``total`` = a zero
    row where a particle has fewer than K terms) and the number of rows ``total``."""
    flat = np.concatenate([np.asarray(i, np.int64).reshape(-1) for i in indices])
    total = len(flat)
    per_particle = [np.flatnonzero(flat == p) for p in range(n)]
    width = max(1, max(len(r) for r in per_particle))
    table = np.full((n, width), total, np.int64)
    for p, rows in enumerate(per_particle):
        table[p, : len(rows)] = rows
    return table, total


def _gathered(n: int, terms) -> jnp.ndarray:
    table, _ = gather_table(n, [index for index, _, _ in terms])
    rows = [rows if sign > 0 else -rows for _, sign, rows in terms]
    padded = jnp.concatenate([*rows, jnp.zeros((1, rows[0].shape[-1]), rows[0].dtype)])
    return jnp.sum(padded[table], axis=1)


def spread_form(n_rows: int, n_particles: int, dense_limit: int) -> str:
    """How a population's per-bond rows become particle forces: "dense" (a product with the
    signed incidence of every restart, [P D, B]: fastest while rows x particles is at most
    ``dense_limit``) or "gathered" (each particle's rows by index: work grows with the bond
    ends, not with bonds x particles)."""
    return "dense" if n_rows * n_particles <= dense_limit else "gathered"
