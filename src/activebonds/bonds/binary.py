"""Binary viscoelastic bonds and mechanical-neural bonds (DESIGN.md §2).

Between particles i and j: d = x_j - x_i, L = |d|, u = d / L, Ldot = (v_j - v_i) . u; tension
f = k (L - l0) + c Ldot, F_i += f u, F_j -= f u (positive tension pulls together). A neural
bond's neuron b reads every other binary bond j: a_b = tanh(sum_{j != b} (wL_bj e_j +
wV_bj Ldot_j) - theta_b + w_b sin(2 pi f t + phi_b)) with e_j = L_j - l0_j, and its tension
gains g_b a_b. The last term is the rhythmic drive (a phase oscillator, central-pattern-
generator style): drive weight w_b and phase phi_b per bond (``drive_weight``,
``drive_phase``), one frequency f for the whole model (the model file's ``[drive] frequency``,
gene ``drive.frequency``), t the time from the first frame. Without a ``[drive]`` table every
w_b is 0 and the term adds exactly zero.

The passive part is linear in (k, k l0, c), which the exact least squares solves for; the
neurons are switched off there (their gains and drive weights at 0).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .accumulate import accumulate
from .kind import NON_NEGATIVE, POSITIVE, BondKind, LinearPart, Parameter, spread


def kinematics(topology, x, v):
    """Per bond: unit vector u (i -> j), length L, elongation rate Ldot."""
    i, j = topology["particles"][:, 0], topology["particles"][:, 1]
    d = x[j] - x[i]
    length = jnp.sqrt(jnp.sum(d * d, axis=-1))
    u = d / length[:, None]
    rate = jnp.sum((v[j] - v[i]) * u, axis=-1)
    return u, length, rate


def activation(params, n: int, elongation, rate, t=0.0):
    """Neuron b: a_b = tanh(sum_{j != b} (wL_bj e_j + wV_bj Ldot_j) - theta_b
    + w_b sin(2 pi f t + phi_b)) (the drive term only where ``params`` has drive weights)."""
    off = 1.0 - np.eye(n)
    # one matrix-vector product (a batched product once vmapped over states and individuals)
    drive = (params["length_weights"] * off) @ elongation + (params["rate_weights"] * off) @ rate
    net = drive - params["threshold"]
    if "drive_weight" in params:  # absent from hand-made parameter dicts (older tests)
        phase = 2.0 * jnp.pi * params["drive_frequency"] * t + params["drive_phase"]
        net = net + params["drive_weight"] * jnp.sin(phase)
    return jnp.tanh(net)


def forces(params, topology, x, v, t):
    u, length, rate = kinematics(topology, x, v)
    elongation = length - params["rest_length"]
    tension = params["stiffness"] * elongation + params["damping"] * rate
    neural = topology["neural"]
    if neural.any():
        a = activation(params, len(neural), elongation, rate, t)
        tension = tension + jnp.where(neural, params["gain"] * a, 0.0)
    f = tension[:, None] * u
    pairs = topology["particles"]
    return accumulate(x.shape[0], [(pairs[:, 0], 1, f), (pairs[:, 1], -1, f)])


def activity(params, topology, x, v, t=0.0):
    """Activations of the bonds' neurons at a state and time (0 for non-neural bonds)."""
    _, length, rate = kinematics(topology, x, v)
    neural = topology["neural"]
    a = activation(params, len(neural), length - params["rest_length"], rate, t)
    return jnp.where(neural, a, 0.0)


def _cannot_be_zero(field, values, index, genes, neural) -> bool:
    """Whether some neural bond's ``field`` is fixed non-zero or free with 0 outside its bounds."""
    ids = np.asarray(index[field])
    free = ids >= 0
    lows = np.array([genes[g].lower if g >= 0 else 0.0 for g in ids])
    highs = np.array([genes[g].upper if g >= 0 else 0.0 for g in ids])
    fixed_on = neural & ~free & (np.asarray(values[field]) != 0)
    no_zero = neural & free & ((lows > 0) | (highs < 0))
    return bool(fixed_on.any() or no_zero.any())


def _switch_off(values, index, topology, genes):
    neural = np.asarray(topology["neural"], bool)
    if neural.any():
        for field in ("gain", "drive_weight"):
            if _cannot_be_zero(field, values, index, genes, neural):
                raise ValueError(
                    f"least squares: a neural bond's {field} must be able to be 0 (the neurons "
                    "are switched off; their terms do not enter linearly)"
                )
            values[field] = np.where(neural, 0.0, values[field])
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
    off=("stiffness", "damping"),
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
        Parameter(
            "drive_weight",
            "drive_weight",
            0.0,
            lambda v: (-5.0, 5.0),
            log=False,
            when=_NEURAL,
            needs="drive",
        ),
        Parameter(
            "drive_phase",
            "drive_phase",
            0.0,
            lambda v: (-math.pi, math.pi),
            log=False,
            when=_NEURAL,
            needs="drive",
        ),
    ),
    shared=(
        Parameter(
            "drive.frequency",
            "drive_frequency",
            0.0,
            lambda v: (v / 2, v * 2),
            check=POSITIVE,
            when=_NEURAL,
        ),
    ),
    forces=forces,
    timed=True,
    flags=(_NEURAL,),
    what="binary bonds",
    activity=activity,
    linear=LinearPart(frozenset({"stiffness", "rest_length", "damping"}), _switch_off, _columns),
)
