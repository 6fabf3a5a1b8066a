"""Unary spring + damper, a particle to the environment (DESIGN.md §2).

F_p += -k_u (x_p - a) - c_u v_p, with the anchor ``a`` fixed or identified (genes
``anchor[axis]``). Linear in (k, k a, c): the exact least squares solves for all three.
"""

from __future__ import annotations

import numpy as np

from .accumulate import accumulate
from .kind import NON_NEGATIVE, BondKind, LinearPart, Parameter, spread


def forces(params, topology, x, v):
    idx = topology["particles"][:, 0]
    f = (
        -params["stiffness"][:, None] * (x[idx] - params["anchor"])
        - params["damping"][:, None] * v[idx]
    )
    return accumulate(x.shape[0], [(idx, 1, f)])


def _switch_off(values, index, topology, genes):
    values["stiffness"][:] = 0.0
    values["damping"][:] = 0.0
    return values


def _columns(values, index, topology, x, v, unknowns):
    """F_p += -k x_p + (k a) - c v_p: unknowns k, k a (per axis) and c where free."""
    d = x.shape[-1]
    known = unknowns.known
    for n, p in enumerate(np.asarray(topology["particles"][:, 0])):
        gk, gc = int(index["stiffness"][n]), int(index["damping"][n])
        k, c = float(values["stiffness"][n]), float(values["damping"][n])
        ga = [int(index["anchor"][n, a]) for a in range(d)]
        anchor = np.asarray(values["anchor"][n], np.float64)
        if gk >= 0:
            unknowns.gene(gk)[:, p] -= x[:, p]
        else:
            known[:, p] -= k * x[:, p]
        for a in range(d):
            if ga[a] >= 0 and gk >= 0:
                unknowns.product(gk, ga[a])[:, p, a] += 1.0
            elif ga[a] >= 0:
                unknowns.gene(ga[a])[:, p, a] += k
            elif gk >= 0:
                unknowns.gene(gk)[:, p, a] += anchor[a]
            else:
                known[:, p, a] += k * anchor[a]
        if gc >= 0:
            unknowns.gene(gc)[:, p] -= v[:, p]
        else:
            known[:, p] -= c * v[:, p]


KIND = BondKind(
    name="unary",
    arity=1,
    parameters=(
        Parameter("stiffness", "stiffness", 0.0, spread(100, (0.0, 1e3)), check=NON_NEGATIVE),
        Parameter("damping", "damping", 0.0, spread(100, (0.0, 10.0)), check=NON_NEGATIVE),
        Parameter("anchor", "anchor", 0.0, lambda v: (v - 1.0, v + 1.0), form="vector"),
    ),
    forces=forces,
    internal=False,
    what="unary springs",
    linear=LinearPart(frozenset({"stiffness", "damping", "anchor"}), _switch_off, _columns),
)
