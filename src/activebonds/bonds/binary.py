"""Binary viscoelastic bonds and mechanical-neural bonds (DESIGN.md §2).

Between particles i and j: d = x_j - x_i, L = |d|, u = d / L, Ldot = (v_j - v_i) . u; tension
f = k (L - l0) + c Ldot, F_i += f u, F_j -= f u (positive tension pulls together). A neural
bond's neuron b reads every other binary bond j: a_b = tanh(sum_{j != b} (wL_bj e_j +
wV_bj Ldot_j) - theta_b + w_b sin(2 pi f t + phi_b)) with e_j = L_j - l0_j, and its tension
gains g_b a_b. The last term is the rhythmic drive (a phase oscillator, central-pattern-
generator style): drive weight w_b and phase phi_b per bond (``drive_weight``,
``drive_phase``), one frequency f for the whole model (the model file's ``[drive] frequency``,
gene ``drive.frequency``), t the time from the first frame. Without a ``[drive]`` table every
w_b is 0 and the term adds exactly zero. An entrained drive (``[drive] coupling``) replaces
2 pi f t by its phase psi, a state of the model (:mod:`activebonds.physics.phase`) that the
integrator writes into the parameters as ``drive_state``; its frequency, gain and start phase
are shared parameters held by the neural bonds like ``drive_frequency``.

The passive part is linear in (k, k l0, c), which the exact least squares solves for; the
neurons are switched off there (their gains and drive weights at 0).
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .accumulate import accumulate, gather_table, spread_form
from .kind import (
    DAMPING,
    NON_NEGATIVE,
    POSITIVE,
    STIFFNESS,
    BondKind,
    LinearPart,
    MujocoForm,
    Parameter,
    PopulationForm,
)


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
    + w_b sin(2 pi f t + phi_b)) (the drive term only where ``params`` has drive weights);
    with an entrained drive, ``w_b sin(psi + phi_b)``, psi the drive's state."""
    off = 1.0 - np.eye(n)
    # one matrix-vector product (a batched product once vmapped over states and individuals)
    drive = (params["length_weights"] * off) @ elongation + (params["rate_weights"] * off) @ rate
    net = drive - params["threshold"]
    if DRIVE_STATE in params:  # an entrained drive: its phase psi, a state of the model
        net = net + params["drive_weight"] * jnp.sin(params[DRIVE_STATE] + params["drive_phase"])
    elif "drive_weight" in params:  # absent from hand-made parameter dicts (older tests)
        net = net + rhythm(
            params["drive_weight"], params["drive_frequency"], params["drive_phase"], t
        )
    return jnp.tanh(net)


# The entrained drive's phase psi, set in the kind's parameters by the integrator at every
# force evaluation (:func:`activebonds.physics.phase.at_phase`): a state, not a gene.
DRIVE_STATE = "drive_state"


def passive(stiffness, damping, elongation, rate):
    """The viscoelastic tension k e + c Ldot (any shapes that broadcast)."""
    return stiffness * elongation + damping * rate


def rhythm(weight, frequency, phase, t):
    """The rhythmic drive of a neuron's input, w sin(2 pi f t + phi)."""
    return weight * jnp.sin(2.0 * jnp.pi * frequency * t + phase)


def forces(params, topology, x, v, t):
    u, length, rate = kinematics(topology, x, v)
    elongation = length - params["rest_length"]
    tension = passive(params["stiffness"], params["damping"], elongation, rate)
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
        # two coincident ends (e.g. two missing markers at one filled place in a restart
        # state whose rows do not count): no direction, no force
        u = np.divide(dvec, length, out=np.zeros_like(dvec), where=length > 0)
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


# ----------------------------------------------------------------------------- population form
# The same law for a whole population at fixed restart states (the ES's one-step cost): L, Ldot
# and u do not depend on the genome, so the neuron inputs of every individual are one matrix
# product, [S, 2B] @ [2B, N B] (restarts x [L, Ldot] against every individual's off-diagonal
# weights), plus a bias per individual (-W_L l0 - theta and the rhythmic drive); the tensions
# become particle forces by a product with the fixed u-weighted signed incidence of each
# restart (or, for large models, gathered by particle).


def _population_prepare(topology, x0, v0, n_particles: int, dtype, dense_limit: int) -> dict:
    """Per restart: lengths L [S, B, 1], rates Ldot [S, B, 1], the neuron inputs [S, 2B], and
    the map from tensions to particle forces: dense [S, P D, B] (``+u`` at a bond's first
    particle, ``-u`` at its second) or gathered by particle; and the bonds' neural flags."""
    pairs = np.asarray(topology["particles"])
    i, j = pairs[:, 0], pairs[:, 1]
    d = x0[:, j] - x0[:, i]
    length = np.linalg.norm(d, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = d / length[..., None]
    rate = np.sum((v0[:, j] - v0[:, i]) * u, axis=-1)
    s, b, dim = u.shape
    out = {
        "length": length[..., None],
        "rate": rate[..., None],
        "inputs": np.concatenate([length, rate], axis=1),
    }
    if spread_form(b, n_particles, dense_limit) == "dense":
        incidence = np.zeros((s, n_particles, dim, b))
        incidence[:, i, :, np.arange(b)] += u.transpose(1, 0, 2)
        incidence[:, j, :, np.arange(b)] -= u.transpose(1, 0, 2)
        out["spread"] = incidence.reshape(s, n_particles * dim, b)
    else:  # particle p sums the tensions of bonds table[p] along ends[:, p] (0 past its ends)
        table, total = gather_table(n_particles, [i, j])
        bond = np.where(table < total, table % b, 0)
        sign = np.where(table < total, np.where(table < b, 1.0, -1.0), 0.0)
        out["ends"] = sign[None, :, :, None] * u[:, bond]  # [S, P, K, D]
    out = {k: jnp.asarray(v, dtype) for k, v in out.items()}
    if "ends" in out:
        out["bond"] = bond  # [P, K], an index
    out["neural"] = np.asarray(topology["neural"], bool)
    return out


def _population_forces(params, prepared, t0, n_p: int, dim: int):
    """Forces of the binary bonds of every individual at every restart: [S, P, D, N]."""
    length, rate, neural = prepared["length"], prepared["rate"], prepared["neural"]  # [S, B, 1]
    elongation = length - params["rest_length"].T[None]  # [S, B, N]
    tension = passive(params["stiffness"].T[None], params["damping"].T[None], elongation, rate)
    if neural.any():
        b = len(neural)
        off = jnp.asarray(1.0 - np.eye(b), length.dtype)
        w_len = params["length_weights"] * off  # [N, B, B]
        w_rate = params["rate_weights"] * off
        # neuron inputs: [S, 2B] @ [2B, B N] -> [S, B, N]
        n = w_len.shape[0]
        weights = jnp.concatenate([w_len, w_rate], axis=2).transpose(2, 1, 0)  # [2B, B, N]
        net = (prepared["inputs"] @ weights.reshape(2 * b, b * n)).reshape(-1, b, n)
        bias = -jnp.einsum("nbj,nj->bn", w_len, params["rest_length"]) - params["threshold"].T
        net = net + bias[None]
        if "drive_weight" in params:
            freq = jnp.broadcast_to(params["drive_frequency"], params["rest_length"].shape).T
            t = t0[:, None, None]
            net = net + rhythm(
                params["drive_weight"].T[None], freq[None], params["drive_phase"].T[None], t
            )
        gain = jnp.where(jnp.asarray(neural)[:, None], params["gain"].T, 0.0)  # [B, N]
        tension = tension + gain[None] * jnp.tanh(net)
    n_s, n = tension.shape[0], tension.shape[-1]
    if "spread" in prepared:  # [S, P D, B] @ [S, B, N]
        return jnp.matmul(prepared["spread"], tension).reshape(n_s, n_p, dim, n)
    bond, ends = prepared["bond"], prepared["ends"]  # [P, K], [S, P, K, D]
    return jnp.einsum("spkd,spkn->spdn", ends, tension[:, bond])


def _phase(key: str, field: str, **kw) -> Parameter:
    """A phase (radians, 0 by default), searched linearly over (-pi, pi)."""
    return Parameter(key, field, 0.0, lambda v: (-math.pi, math.pi), log=False, **kw)


def drive_parameters(when: str | None) -> tuple[Parameter, ...]:
    """The rhythmic drive's model-level numbers (``[drive]``), shared by every kind that reads
    the drive (one gene each whatever the kinds): its frequency, and an entrained drive's
    coupling gain, its second signal's gain (either sign) and its start phase; taken by the
    bonds with flag ``when`` (None: every bond)."""
    return (
        Parameter(
            "drive.frequency",
            "drive_frequency",
            0.0,
            lambda v: (v / 2, v * 2),
            check=POSITIVE,
            when=when,
        ),
        Parameter(
            "drive.coupling.gain",
            "drive_gain",
            0.0,
            lambda v: (0.0, max(100.0, 2 * abs(v))),
            log=False,
            check=NON_NEGATIVE,
            when=when,
        ),
        Parameter(
            "drive.coupling.quadrature.gain",
            "drive_quadrature_gain",
            0.0,
            lambda v: (-max(100.0, 2 * abs(v)), max(100.0, 2 * abs(v))),
            log=False,
            when=when,
        ),
        _phase("drive.coupling.start_phase", "drive_start", when=when),
    )


_NEURAL = "neural"


def _mujoco_refusal(bond) -> str | None:
    """A neuron's tension depends on every other bond's state: no MJCF element."""
    return "neural bonds" if getattr(bond, _NEURAL, False) else None


KIND = BondKind(
    off=("stiffness", "damping"),
    name="binary",
    arity=2,
    parameters=(
        STIFFNESS,
        Parameter(
            "rest_length",
            "rest_length",
            None,
            lambda v: (0.5 * v, 1.5 * v) if v > 0 else (0.0, 1.0),
            check=NON_NEGATIVE,
        ),
        DAMPING,
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
        _phase("drive_phase", "drive_phase", when=_NEURAL, needs="drive"),
    ),
    shared=drive_parameters(_NEURAL),
    forces=forces,
    timed=True,
    flags=(_NEURAL,),
    what="binary bonds",
    noun="spring",
    activity=activity,
    linear=LinearPart(frozenset({"stiffness", "rest_length", "damping"}), _switch_off, _columns),
    population=PopulationForm(_population_prepare, _population_forces),
    mujoco=MujocoForm("tendon", _mujoco_refusal),
)
