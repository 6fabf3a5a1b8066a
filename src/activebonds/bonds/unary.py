"""Unary spring + damper, a particle to the environment (DESIGN.md §2).

F_p += -k_u (x_p - a(t)) - c_u (v_p - u), with the anchor ``a(t) = a + u t`` moving at the
constant ``anchor_velocity`` u (default zero; e.g. a marker tied to a treadmill frame), t the
time from the first frame of the data window; ``a`` and ``u`` fixed or identified (genes
``anchor[axis]``, ``anchor_velocity[axis]``). Linear in (k, k a, c) for a fixed u: the exact
least squares solves for all three, and refuses a free u (its terms k u t and c u would need
two products of one gene).
"""

from __future__ import annotations

import numpy as np

from .accumulate import accumulate
from .kind import DAMPING, STIFFNESS, BondKind, LinearPart, MujocoForm, Parameter


def forces(params, topology, x, v, t):
    idx = topology["particles"][:, 0]
    u = params["anchor_velocity"]
    k, c = params["stiffness"][:, None], params["damping"][:, None]
    f = -k * (x[idx] - (params["anchor"] + u * t)) - c * (v[idx] - u)
    return accumulate(x.shape[0], [(idx, 1, f)])


def _switch_off(values, index, topology, genes):
    moving = np.asarray(index["anchor_velocity"])
    if (moving >= 0).any():
        raise ValueError(
            "least squares: a free anchor_velocity does not enter linearly (k u t and c u are "
            "products of one gene with two others); fix it"
        )
    values["stiffness"][:] = 0.0
    values["damping"][:] = 0.0
    return values


def _columns(values, index, topology, x, v, unknowns):
    """F_p += -k x_p + (k a) + k u t - c (v_p - u): unknowns k, k a (per axis) and c where
    free; the anchor velocity u is fixed (``_switch_off`` refuses a free one)."""
    d = x.shape[-1]
    known = unknowns.known
    t = np.asarray(unknowns.time, np.float64)[:, None]  # [S, 1] the start frames' times
    for n, p in enumerate(np.asarray(topology["particles"][:, 0])):
        gk, gc = int(index["stiffness"][n]), int(index["damping"][n])
        k, c = float(values["stiffness"][n]), float(values["damping"][n])
        ga = [int(index["anchor"][n, a]) for a in range(d)]
        anchor = np.asarray(values["anchor"][n], np.float64)
        u = np.asarray(values["anchor_velocity"][n], np.float64)
        if gk >= 0:
            unknowns.gene(gk)[:, p] -= x[:, p] - u * t
        else:
            known[:, p] -= k * (x[:, p] - u * t)
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
            unknowns.gene(gc)[:, p] -= v[:, p] - u
        else:
            known[:, p] -= c * (v[:, p] - u)


def _mujoco_refusal(bond) -> str | None:
    """A moving anchor: a slide joint's spring reference is fixed."""
    velocity = bond.anchor_velocity
    if velocity is None:
        return None
    values = velocity if isinstance(velocity, list) else velocity.value
    if not any(float(v) != 0.0 for v in values):
        return None
    return "unary bonds with a moving anchor (anchor_velocity)"


KIND = BondKind(
    off=("stiffness", "damping"),
    name="unary",
    arity=1,
    parameters=(
        STIFFNESS,
        DAMPING,
        Parameter("anchor", "anchor", 0.0, lambda v: (v - 1.0, v + 1.0), form="vector"),
        Parameter(
            "anchor_velocity", "anchor_velocity", 0.0, lambda v: (v - 1.0, v + 1.0), form="vector"
        ),
    ),
    forces=forces,
    timed=True,
    internal=False,
    what="unary springs",
    noun="unary spring",
    linear=LinearPart(frozenset({"stiffness", "damping", "anchor"}), _switch_off, _columns),
    mujoco=MujocoForm("anchor", _mujoco_refusal),
)
