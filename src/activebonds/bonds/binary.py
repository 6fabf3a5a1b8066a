"""Binary viscoelastic bonds and mechanical-neural bonds (DESIGN.md §2).

Between particles i and j: d = x_j - x_i, L = |d|, u = d / L, Ldot = (v_j - v_i) . u; tension
f = k (L - l0) + c Ldot, F_i += f u, F_j -= f u (positive tension pulls together). A neural
bond's neuron b reads every other binary bond j: a_b = tanh(sum_{j != b} (wL_bj e_j +
wV_bj Ldot_j) - theta_b) with e_j = L_j - l0_j, and its tension gains g_b a_b.

The passive part is linear in (k, k l0, c), which the exact least squares solves for; the
neurons are switched off there (their gains at 0).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .accumulate import accumulate
from .kind import NON_NEGATIVE, BondKind, LinearPart, Parameter, spread


def kinematics(topology, x, v):
    """Per bond: unit vector u (i -> j), length L, elongation rate Ldot."""
    i, j = topology["particles"][:, 0], topology["particles"][:, 1]
    d = x[j] - x[i]
    length = jnp.sqrt(jnp.sum(d * d, axis=-1))
    u = d / length[:, None]
    rate = jnp.sum((v[j] - v[i]) * u, axis=-1)
    return u, length, rate


def activation(params, n: int, elongation, rate):
    """Neuron b: a_b = tanh(sum_{j != b} (wL_bj e_j + wV_bj Ldot_j) - theta_b)."""
    off = 1.0 - np.eye(n)
    drive = jnp.sum(params["length_weights"] * off * elongation[None, :], axis=-1) + jnp.sum(
        params["rate_weights"] * off * rate[None, :], axis=-1
    )
    return jnp.tanh(drive - params["threshold"])


def forces(params, topology, x, v):
    u, length, rate = kinematics(topology, x, v)
    elongation = length - params["rest_length"]
    tension = params["stiffness"] * elongation + params["damping"] * rate
    neural = topology["neural"]
    if neural.any():
        a = activation(params, len(neural), elongation, rate)
        tension = tension + jnp.where(neural, params["gain"] * a, 0.0)
    f = tension[:, None] * u
    pairs = topology["particles"]
    return accumulate(x.shape[0], [(pairs[:, 0], 1, f), (pairs[:, 1], -1, f)])


def activity(params, topology, x, v):
    """Activations of the bonds' neurons at a state (0 for non-neural bonds)."""
    _, length, rate = kinematics(topology, x, v)
    neural = topology["neural"]
    a = activation(params, len(neural), length - params["rest_length"], rate)
    return jnp.where(neural, a, 0.0)


def _switch_off(values, index, topology, genes):
    neural = np.asarray(topology["neural"], bool)
    if neural.any():
        gains = np.asarray(index["gain"])
        gain_free = gains >= 0
        lows = np.array([genes[g].lower if g >= 0 else 0.0 for g in gains])
        highs = np.array([genes[g].upper if g >= 0 else 0.0 for g in gains])
        fixed_on = neural & ~gain_free & (np.asarray(values["gain"]) != 0)
        no_zero = neural & gain_free & ((lows > 0) | (highs < 0))
        if fixed_on.any() or no_zero.any():
            raise ValueError(
                "least squares: a neural bond's gain must be able to be 0 (the neurons are "
                "switched off; their terms do not enter linearly)"
            )
        values["gain"] = np.where(neural, 0.0, values["gain"])
    values["stiffness"][:] = 0.0
    values["damping"][:] = 0.0
    return values


def _columns(values, index, topology, x, v, unknowns):
    """Tension k L - (k l0) + c Ldot: unknowns k, k l0 and c where free."""
    pairs = np.asarray(topology["particles"])
    i, j = pairs[:, 0], pairs[:, 1]
    for b in range(len(pairs)):
        dvec = x[:, j[b]] - x[:, i[b]]
        length = np.linalg.norm(dvec, axis=-1)[:, None]
        u = dvec / length
        rate = np.sum((v[:, j[b]] - v[:, i[b]]) * u, axis=-1)[:, None]
        gk, gl = int(index["stiffness"][b]), int(index["rest_length"][b])
        gc = int(index["damping"][b])
        k, l0 = float(values["stiffness"][b]), float(values["rest_length"][b])
        c = float(values["damping"][b])
        terms = []  # (column or None for the known part, tension per unit)
        if gk >= 0 and gl >= 0:
            terms += [
                (unknowns.gene(gk), length),
                (unknowns.product(gk, gl), -np.ones_like(length)),
            ]
        elif gk >= 0:
            terms += [(unknowns.gene(gk), length - l0)]
        elif gl >= 0:
            terms += [(None, k * length), (unknowns.gene(gl), -k * np.ones_like(length))]
        else:
            terms += [(None, k * (length - l0))]
        terms += [(unknowns.gene(gc), rate)] if gc >= 0 else [(None, c * rate)]
        for column, tension in terms:
            target = unknowns.known if column is None else column
            target[:, i[b]] += tension * u
            target[:, j[b]] -= tension * u


_NEURAL = "neural"
KIND = BondKind(
    name="binary",
    arity=2,
    parameters=(
        Parameter("stiffness", "stiffness", 0.0, spread(100, (0.0, 1e3)), check=NON_NEGATIVE),
        Parameter(
            "rest_length",
            "rest_length",
            None,
            lambda v: (0.5 * v, 1.5 * v) if v > 0 else (0.0, 1.0),
            check=NON_NEGATIVE,
        ),
        Parameter("damping", "damping", 0.0, spread(100, (0.0, 10.0)), check=NON_NEGATIVE),
        Parameter("gain", "gain", 1.0, lambda v: (0.0, max(100.0, 2 * abs(v))), when=_NEURAL),
        Parameter("threshold", "threshold", 0.0, lambda v: (-5.0, 5.0), when=_NEURAL),
        Parameter(
            "weights", "length_weights", 0.0, log=False, form="weights", part="length", when=_NEURAL
        ),
        Parameter(
            "weights", "rate_weights", 0.0, log=False, form="weights", part="rate", when=_NEURAL
        ),
    ),
    forces=forces,
    flags=(_NEURAL,),
    what="binary bonds",
    activity=activity,
    linear=LinearPart(frozenset({"stiffness", "rest_length", "damping"}), _switch_off, _columns),
)
