"""Ternary (flexion) springs on particles (i, j, k), the angle theta at the middle one j.

Energy E = 1/2 k_f (cos theta - cos theta0)^2; forces F = -grad E on all three particles (they
sum to zero, without torque). Not linear in its parameters: no least-squares part.
"""

from __future__ import annotations

import math

import jax.numpy as jnp

from .accumulate import accumulate
from .kind import ANGLE, STIFFNESS, BondKind, Parameter


def forces(params, topology, x, v):
    t = topology["particles"]
    i, j, k = t[:, 0], t[:, 1], t[:, 2]
    a = x[i] - x[j]
    b = x[k] - x[j]
    na = jnp.sqrt(jnp.sum(a * a, axis=-1))[:, None]
    nb = jnp.sqrt(jnp.sum(b * b, axis=-1))[:, None]
    cos = jnp.sum(a * b, axis=-1)[:, None] / (na * nb)
    dcos_da = b / (na * nb) - cos * a / (na * na)
    dcos_db = a / (na * nb) - cos * b / (nb * nb)
    s = -params["stiffness"][:, None] * (cos - jnp.cos(params["rest_angle"])[:, None])
    fi, fk = s * dcos_da, s * dcos_db
    return accumulate(x.shape[0], [(i, 1, fi), (k, 1, fk), (j, -1, fi + fk)])


KIND = BondKind(
    off=("stiffness",),
    name="ternary",
    arity=3,
    parameters=(
        STIFFNESS,
        Parameter(
            "rest_angle",
            "rest_angle",
            None,
            lambda v: (0.0, math.pi),
            check=ANGLE,
            note=" (radians)",
        ),
    ),
    forces=forces,
    what="flexion springs",
    noun="flexion spring",
)
