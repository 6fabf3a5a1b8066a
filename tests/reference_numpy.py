"""A plain NumPy reference of the physics (DESIGN.md §2), written from the equations alone.

Deliberately simple: explicit Python loops over particles and bonds, float64 throughout, no
code shared with :mod:`activebonds.physics` or :mod:`activebonds.bonds`. ``params`` and
``topo`` are any objects with the attributes of :class:`activebonds.model.Params`
(``mass``, ``gravity``, ``bonds[kind][field]``) and :class:`activebonds.model.Topology`
(``bonds[kind]["particles"]``, flags such as ``bonds["binary"]["neural"]``, ``disabled``).

One oracle per bond kind, ``KIND_FORCES[name](p, t, x, v)`` with ``p`` and ``t`` that kind's
parameters and topology; a new kind adds its own (here or in its test file) and, if it is
conservative, its energy to ``KIND_ENERGIES``. Equations (SI units):

* uniform field: F_p += m_p g
* unary spring + damper: F_p += -k_u (x_p - a - u t) - c_u (v_p - u), u the anchor velocity,
  t the time (an oracle that depends on time takes it as the keyword ``time``)
* binary bond i-j: d = x_j - x_i, L = |d|, u = d / L, Ldot = (v_j - v_i) . u,
  tension f = k (L - l0) + c Ldot (+ g_b a_b if neural), F_i += f u, F_j -= f u
* neuron of bond b: a_b = tanh(sum_{j != b} (wL_bj e_j + wV_bj Ldot_j) - theta_b
  + w_b sin(2 pi f t + phi_b)), e_j = L_j - l0_j; the rhythmic drive's weight w_b, phase phi_b
  and (model-wide) frequency f are 0 when ``p`` lacks them
* entrained drive: its phase psi replaces 2 pi f t, d psi/dt = 2 pi f - sigma s cos psi, s the
  height (last coordinate) of the coupling's particle, or the distance between its two
  particles, minus its offset (with a second signal s_b, gain sigma_b: - sigma_b s_b sin psi
  added); advanced by explicit Euler from each step's start (``entrained_rollout``)
* periodic force on p: F_p += sum_{h=1..8} C_h cos(h psi) + S_h sin(h psi), psi the drive's
  phase (2 pi f t, or the entrained psi)
* ternary flexion (i, j, k), angle th at j: E = 1/2 k_f (cos th - cos th0)^2, F = -grad E
* contact of p with the plane n . x = h (n a unit vector): d = h - n . x_p; while d > 0,
  Fn = max(0, k d - c n . v_p) along n, friction Ft = -mu Fn vt / sqrt(|vt|^2 + eps^2) with
  w = v_p - s (s the surface velocity), vt = w - (n . w) n, eps = 1e-3 m/s; energy 1/2 k d^2
"""

from __future__ import annotations

import inspect
import math

import numpy as np


def _arr(a) -> np.ndarray:
    return np.asarray(a, dtype=np.float64)


def _particles(t, arity: int) -> np.ndarray:
    return np.asarray(t["particles"]).reshape(-1, arity)


# --------------------------------------------------------------------------------------------
# Forces, one kind at a time
# --------------------------------------------------------------------------------------------


def uniform_field_force(params, topo, x, v) -> np.ndarray:
    x = _arr(x)
    mass, g = _arr(params.mass), _arr(params.gravity)
    f = np.zeros_like(x)
    for p in range(x.shape[0]):
        f[p] = mass[p] * g
    return f


def unary_force(p, t, x, v, time=0.0) -> np.ndarray:
    x, v = _arr(x), _arr(v)
    f = np.zeros_like(x)
    for b, (q,) in enumerate(_particles(t, 1)):
        k = float(p["stiffness"][b])
        c = float(p["damping"][b])
        u = _arr(p["anchor_velocity"][b]) if "anchor_velocity" in p else np.zeros(x.shape[1])
        a = _arr(p["anchor"][b]) + u * float(time)
        f[q] += -k * (x[q] - a) - c * (v[q] - u)
    return f


def bond_state(t, x, v):
    """Per binary bond: lengths L, elongation rates Ldot, unit vectors u (from i to j)."""
    x, v = _arr(x), _arr(v)
    pairs = _particles(t, 2)
    n = pairs.shape[0]
    lengths = np.zeros(n)
    rates = np.zeros(n)
    units = np.zeros((n, x.shape[1]))
    for b, (i, j) in enumerate(pairs):
        d = x[j] - x[i]
        length = math.sqrt(float(np.dot(d, d)))
        u = d / length
        lengths[b] = length
        units[b] = u
        rates[b] = float(np.dot(v[j] - v[i], u))
    return lengths, rates, units


def neuron_activations(p, t, x, v, time=0.0, phase=None) -> np.ndarray:
    """a_b for every binary bond (computed for all; only neural bonds use it) at ``time``;
    with an entrained drive's ``phase`` psi the drive term is w_b sin(psi + phi_b)."""
    lengths, rates, _ = bond_state(t, x, v)
    e = lengths - _arr(p["rest_length"])
    w_len, w_rate = _arr(p["length_weights"]), _arr(p["rate_weights"])
    n = len(lengths)
    zeros = np.zeros(n)
    w_drive = _arr(p.get("drive_weight", zeros))
    phi = _arr(p.get("drive_phase", zeros))
    freq = _arr(p.get("drive_frequency", zeros))
    acts = np.zeros(n)
    for b in range(n):
        s = 0.0
        for j in range(n):
            if j != b:
                s += w_len[b, j] * e[j] + w_rate[b, j] * rates[j]
        s -= float(p["threshold"][b])
        clock = 2.0 * math.pi * float(freq[b]) * time if phase is None else float(phase)
        s += float(w_drive[b]) * math.sin(clock + float(phi[b]))
        acts[b] = math.tanh(s)
    return acts


def binary_force(p, t, x, v, time=0.0, phase=None) -> np.ndarray:
    x = _arr(x)
    f = np.zeros_like(x)
    pairs = _particles(t, 2)
    if pairs.shape[0] == 0:
        return f
    lengths, rates, units = bond_state(t, x, v)
    acts = neuron_activations(p, t, x, v, time, phase)
    neural = np.asarray(t["neural"]).reshape(-1)
    for b, (i, j) in enumerate(pairs):
        tension = float(p["stiffness"][b]) * (lengths[b] - float(p["rest_length"][b]))
        tension += float(p["damping"][b]) * rates[b]
        if neural[b]:
            tension += float(p["gain"][b]) * acts[b]
        f[i] += tension * units[b]
        f[j] -= tension * units[b]
    return f


def _cos_and_gradients(xi, xj, xk):
    """cos of the angle at xj between xi - xj and xk - xj, and its gradients wrt xi, xj, xk."""
    a = xi - xj
    b = xk - xj
    la = math.sqrt(float(np.dot(a, a)))
    lb = math.sqrt(float(np.dot(b, b)))
    ua, ub = a / la, b / lb
    cos = float(np.dot(ua, ub))
    # d cos / d a = (ub - cos ua) / |a|, likewise for b; xj enters through both with a minus.
    g_i = (ub - cos * ua) / la
    g_k = (ua - cos * ub) / lb
    g_j = -g_i - g_k
    return cos, g_i, g_j, g_k


def ternary_force(p, t, x, v) -> np.ndarray:
    x = _arr(x)
    f = np.zeros_like(x)
    for n, (i, j, k) in enumerate(_particles(t, 3)):
        cos, g_i, g_j, g_k = _cos_and_gradients(x[i], x[j], x[k])
        # E = 1/2 kf (cos - cos0)^2  ->  dE/dx = kf (cos - cos0) dcos/dx
        dE = float(p["stiffness"][n]) * (cos - math.cos(float(p["rest_angle"][n])))
        f[i] -= dE * g_i
        f[j] -= dE * g_j
        f[k] -= dE * g_k
    return f


CONTACT_EPS = 1e-3  # m/s, the friction's smoothing speed (DESIGN.md §2)


def contact_force(p, t, x, v) -> np.ndarray:
    x, v = _arr(x), _arr(v)
    f = np.zeros_like(x)
    dim = x.shape[1]
    for b, (q,) in enumerate(_particles(t, 1)):
        n = _arr(p["normal"][b])
        n = n / math.sqrt(sum(n[a] * n[a] for a in range(dim)))
        depth = float(p["height"][b]) - sum(n[a] * x[q, a] for a in range(dim))
        if depth <= 0.0:
            continue
        normal_speed = sum(n[a] * v[q, a] for a in range(dim))
        fn = float(p["stiffness"][b]) * depth - float(p["damping"][b]) * normal_speed
        fn = max(0.0, fn)
        w = [v[q, a] - float(p["surface_velocity"][b][a]) for a in range(dim)]
        wn = sum(n[a] * w[a] for a in range(dim))
        vt = [w[a] - wn * n[a] for a in range(dim)]
        speed = math.sqrt(sum(c * c for c in vt) + CONTACT_EPS**2)
        mu = float(p["friction"][b])
        for a in range(dim):
            f[q, a] += fn * n[a] - mu * fn * vt[a] / speed
    return f


def periodic_force(p, t, x, v, time=0.0, phase=None) -> np.ndarray:
    """F_p += sum_h C_h cos(h psi) + S_h sin(h psi), psi the entrained phase ``phase`` or
    the clock 2 pi f t, coefficients ``cos1`` .. ``sin8`` [N, D]."""
    x = _arr(x)
    f = np.zeros_like(x)
    for b, q in enumerate(_particles(t, 1)[:, 0]):
        psi = 2 * math.pi * float(p["drive_frequency"][b]) * time if phase is None else phase
        for h in range(1, 9):
            f[q] += math.cos(h * psi) * _arr(p[f"cos{h}"][b]) + math.sin(h * psi) * _arr(
                p[f"sin{h}"][b]
            )
    return f


KIND_FORCES = {
    "unary": unary_force,
    "binary": binary_force,
    "ternary": ternary_force,
    "contact": contact_force,
    "periodic": periodic_force,
}


def kind_force(kind, params, topo, x, v, time=0.0, phase=None) -> np.ndarray:
    """The forces of one kind's bonds (zero for a disabled kind)."""
    if kind in getattr(topo, "disabled", ()):
        return np.zeros_like(_arr(x))
    oracle = KIND_FORCES[kind]
    if phase is not None and "phase" in inspect.signature(oracle).parameters:
        return oracle(params.bonds[kind], topo.bonds[kind], x, v, time=time, phase=phase)
    if "time" in inspect.signature(oracle).parameters:
        return oracle(params.bonds[kind], topo.bonds[kind], x, v, time=time)
    return oracle(params.bonds[kind], topo.bonds[kind], x, v)


def total_force(params, topo, x, v, time=0.0, phase=None) -> np.ndarray:
    f = uniform_field_force(params, topo, x, v)
    for kind in topo.bonds:
        f = f + kind_force(kind, params, topo, x, v, time, phase)
    return f


# --------------------------------------------------------------------------------------------
# Energy of the conservative part (no dampers, no neurons); x, v may carry leading batch axes
# --------------------------------------------------------------------------------------------


def unary_energy(p, t, x) -> np.ndarray:
    energy = np.zeros(x.shape[:-2])
    for b, (q,) in enumerate(_particles(t, 1)):
        r = x[..., q, :] - _arr(p["anchor"][b])
        energy = energy + 0.5 * float(p["stiffness"][b]) * np.sum(r * r, axis=-1)
    return energy


def binary_energy(p, t, x) -> np.ndarray:
    energy = np.zeros(x.shape[:-2])
    for b, (i, j) in enumerate(_particles(t, 2)):
        length = np.linalg.norm(x[..., j, :] - x[..., i, :], axis=-1)
        energy = (
            energy + 0.5 * float(p["stiffness"][b]) * (length - float(p["rest_length"][b])) ** 2
        )
    return energy


def ternary_energy(p, t, x) -> np.ndarray:
    energy = np.zeros(x.shape[:-2])
    for n, (i, j, k) in enumerate(_particles(t, 3)):
        a = x[..., i, :] - x[..., j, :]
        b = x[..., k, :] - x[..., j, :]
        cos = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
        cos0 = math.cos(float(p["rest_angle"][n]))
        energy = energy + 0.5 * float(p["stiffness"][n]) * (cos - cos0) ** 2
    return energy


def contact_energy(p, t, x) -> np.ndarray:
    """1/2 k d^2 while the particle is below its plane (the undamped, frictionless part)."""
    energy = np.zeros(x.shape[:-2])
    for b, (q,) in enumerate(_particles(t, 1)):
        n = _arr(p["normal"][b])
        n = n / np.linalg.norm(n)
        depth = float(p["height"][b]) - np.sum(x[..., q, :] * n, axis=-1)
        energy = energy + 0.5 * float(p["stiffness"][b]) * np.maximum(depth, 0.0) ** 2
    return energy


def no_energy(p, t, x) -> np.ndarray:
    """A driven force (periodic) stores no potential energy."""
    return np.zeros(np.shape(_arr(x))[:-2])


KIND_ENERGIES = {
    "unary": unary_energy,
    "binary": binary_energy,
    "ternary": ternary_energy,
    "contact": contact_energy,
    "periodic": no_energy,
}


def potential_energy(params, topo, x) -> np.ndarray:
    """Gravity + the springs of every kind. x: [..., P, D]."""
    x = _arr(x)
    mass = _arr(params.mass)
    energy = -np.einsum("p,...pd,d->...", mass, x, _arr(params.gravity))
    for kind in topo.bonds:
        if kind not in getattr(topo, "disabled", ()):
            energy = energy + KIND_ENERGIES[kind](params.bonds[kind], topo.bonds[kind], x)
    return energy


def kinetic_energy(params, v) -> np.ndarray:
    v = _arr(v)
    return 0.5 * np.einsum("p,...pd,...pd->...", _arr(params.mass), v, v)


def energy(params, topo, x, v) -> np.ndarray:
    return kinetic_energy(params, v) + potential_energy(params, topo, x)


# --------------------------------------------------------------------------------------------
# Integrators
# --------------------------------------------------------------------------------------------


def euler_step(params, topo, x, v, h, time=0.0):
    """Semi-implicit Euler: v <- v + h F(x, v) / m, then x <- x + h v (new v)."""
    m = _arr(params.mass)[:, None]
    v_new = _arr(v) + h * total_force(params, topo, x, v, time) / m
    return _arr(x) + h * v_new, v_new


def verlet_step(params, topo, x, v, h, time=0.0):
    """Velocity Verlet; the second force is evaluated at (x_new, v_half)."""
    m = _arr(params.mass)[:, None]
    v_half = _arr(v) + 0.5 * h * total_force(params, topo, x, v, time) / m
    x_new = _arr(x) + h * v_half
    v_new = v_half + 0.5 * h * total_force(params, topo, x_new, v_half, time + h) / m
    return x_new, v_new


STEPS = {"euler": euler_step, "verlet": verlet_step}


def rollout(params, topo, x0, v0, dt, n_frames, substeps=1, method="euler", t0=0.0):
    """Positions of n_frames frames (the first is x0, at time t0), each frame dt after the
    previous; substep k of frame n starts at t0 + n dt + k h."""
    step = STEPS[method]
    h = dt / substeps
    x, v = _arr(x0).copy(), _arr(v0).copy()
    frames = [x.copy()]
    for n in range(n_frames - 1):
        for k in range(substeps):
            x, v = step(params, topo, x, v, h, t0 + n * dt + k * h)
        frames.append(x.copy())
    return np.stack(frames)


def _coupling_signal(c, x) -> float:
    """A coupling signal: the coordinate ``axis`` of one particle, or the distance between
    two, minus ``offset``."""
    ps = c["particles"]
    if len(ps) == 1:
        return float(x[ps[0], c["axis"]]) - c["offset"]
    return float(np.linalg.norm(x[ps[1]] - x[ps[0]])) - c["offset"]


def entrained_rollout(params, topo, x0, v0, dt, n_frames, coupling, substeps=1, t0=0.0):
    """Semi-implicit Euler with an entrained drive: positions [n_frames, P, D] and phases
    [n_frames]. ``coupling``: ``particles`` (one: its coordinate ``axis`` is the signal;
    two: their distance), ``axis``, ``offset`` (m), ``frequency`` (Hz), ``gain`` (rad/s per
    m), ``psi0`` (the phase at x0), optionally ``quadrature`` (a second signal: its
    ``particles``, ``axis``, ``offset`` and ``gain`` sigma_b). Each substep: v <- v + h F(x,
    v, psi)/m, x <- x + h v, psi <- psi + h (2 pi f - sigma s(x_old) cos psi - sigma_b
    s_b(x_old) sin psi)."""
    h = dt / substeps
    m = _arr(params.mass)[:, None]
    x, v, psi = _arr(x0).copy(), _arr(v0).copy(), float(coupling["psi0"])
    frames, phases = [x.copy()], [psi]
    for n in range(n_frames - 1):
        for k in range(substeps):
            time = t0 + n * dt + k * h
            s = _coupling_signal(coupling, x)
            rate = 2.0 * math.pi * coupling["frequency"] - coupling["gain"] * s * math.cos(psi)
            second = coupling.get("quadrature")
            if second is not None:
                rate -= second["gain"] * _coupling_signal(second, x) * math.sin(psi)
            v = v + h * total_force(params, topo, x, v, time, phase=psi) / m
            x = x + h * v
            psi = psi + h * rate
        frames.append(x.copy())
        phases.append(psi)
    return np.stack(frames), np.array(phases)
