"""Summing per-bond force rows into particles without a scatter-add."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np


def accumulate(n: int, terms) -> jnp.ndarray:
    """Sum per-element force rows into particles: ``terms`` is a list of (index array,
    sign, rows [K, D]); returns [n, D]. The topology is static, so this unrolls into plain
    slices and adds (a scatter-add vmapped over a population is slow on CPU)."""
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
