"""What a fit is judged against: the zero-force predictor and the exact floor of a model family.

* **Zero-force baseline** (constant velocity): the one-step prediction with no force at all,
  ``x_{t+1} = 2 x_t - x_{t-1}`` (:func:`~activebonds.identify.judge.predictions.constant_velocity`). A fitted model that does not beat it on frames it never saw
  has learnt nothing that generalises.
* **Momentum floor**: every force of a model made only of bonds (springs, dampers, muscles,
  flexion springs) is internal, so it conserves linear *and* angular momentum: the one-step
  accelerations ``a`` of a frame satisfy ``sum_p m_p a_p = 0`` and ``sum_p m_p x_p x a_p = 0``
  (positions at the frame the forces act on). The smallest one-step error any such model can
  reach is, frame by frame, the least-squares residual of the force-free prediction's error
  outside that subspace. The uniform field (fixed in the model file) only shifts the prediction.

Both use the cost's conventions (one-substep semi-implicit Euler, horizon 1, masked gaps) and
are RMS position errors in mm over the same terms as the fit cost.
"""

from __future__ import annotations

import numpy as np

from ... import bonds
from ...model import Model
from ..costs.windows import make_windows
from .predictions import constant_velocity, zero_force_predictions

__all__ = [  # zero force's predictions are predictions.py's, named here too for its readers
    "model_floor_rms_mm",
    "momentum_floor_rms_mm",
    "zero_force_predictions",
    "zero_force_rms_mm",
    "zero_force_rms_mm_of",
]


def _one_step_terms(positions: np.ndarray, mask: np.ndarray, dt: float, neighbours=None):
    w = make_windows(positions, mask, dt, 1, neighbours=neighbours)
    inertial = constant_velocity(w.x0, w.v0, dt)  # x_t + dt v_t = 2 x_t - x_{t-1}
    return w, w.target[:, 0] - inertial, w.weight[:, 0]  # [S, P, D], [S, P]


def zero_force_rms_mm(positions: np.ndarray, mask: np.ndarray, dt: float, neighbours=None) -> float:
    """RMS one-step error (mm) of the constant-velocity predictor over ``positions``' frames,
    on the terms the cost counts (``neighbours``: a model's bond graph,
    :func:`~activebonds.identify.costs.windows.neighbours_of`; None: every marker present at
    the start)."""
    _, resid, weight = _one_step_terms(positions, mask, dt, neighbours)
    n = weight.sum()
    if n == 0:
        return float("nan")
    return float(np.sqrt(np.sum(weight[..., None] * resid**2) / n) * 1000.0)


def zero_force_rms_mm_of(recordings, neighbours=None) -> float:
    """The zero-force baseline's RMS (mm) over every one-step term of several recordings
    (trajectories; a fit on several at once adds their costs), counted as the cost counts
    them (``neighbours``: as :func:`zero_force_rms_mm`)."""
    sq = n = 0.0
    for d in recordings:
        terms = make_windows(d.positions, d.mask, d.dt, 1, neighbours=neighbours).n_terms
        sq += zero_force_rms_mm(d.positions, d.mask, d.dt, neighbours) ** 2 * terms
        n += terms
    return float(np.sqrt(sq / max(n, 1)))


def _constraints(x: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Rows of C with C a = 0 for internal accelerations a (flattened [P * D]) at positions x.
    Torques are taken about the heaviest particle (the same constraints as about any point,
    given zero net force), whose own lever arm is then exactly 0: so no torque row is a
    near-copy of the force rows when one mass dominates. About the origin (or about a centre
    of mass rounded next to the heavy particle) they differ from them by O(small masses)
    only, and a rank test drops them."""
    n_p, dim = x.shape
    x = x - x[int(np.argmax(mass))]
    rows = []
    for k in range(dim):  # linear momentum
        r = np.zeros((n_p, dim))
        r[:, k] = mass
        rows.append(r.ravel())
    if dim == 2:  # angular momentum: m (x0 a1 - x1 a0)
        r = np.zeros((n_p, 2))
        r[:, 0], r[:, 1] = -mass * x[:, 1], mass * x[:, 0]
        rows.append(r.ravel())
    elif dim == 3:  # (x x a)_k = eps_kij x_i a_j
        for k in range(3):
            i, j = (k + 1) % 3, (k + 2) % 3
            r = np.zeros((n_p, 3))
            r[:, j] = mass * x[:, i]
            r[:, i] = -mass * x[:, j]
            rows.append(r.ravel())
    return np.asarray(rows)


def momentum_floor_rms_mm(
    positions: np.ndarray,
    mask: np.ndarray,
    dt: float,
    mass,
    gravity=None,
    angular: bool = True,
) -> float:
    """The exact lowest one-step RMS error (mm) of any model whose forces are internal (plus a
    known uniform field ``gravity``): per frame, min over accelerations ``a`` with zero net
    force (and zero net torque when ``angular``) of the masked squared error, solved in the
    null space of the constraints."""
    w, resid, weight = _one_step_terms(positions, mask, dt)
    mass = np.asarray(mass, np.float64)
    if gravity is not None:
        resid = resid - dt**2 * np.asarray(gravity, np.float64)[None, None, :]
    n_p, dim = resid.shape[1:]
    total = 0.0
    for s in range(resid.shape[0]):
        obs = np.repeat(weight[s] > 0, dim)
        if not obs.any():
            continue
        c = _constraints(w.x0[s], mass)
        if not angular:
            c = c[:dim]
        # null space of C: the reachable displacements dt^2 a. Each constraint row is scaled
        # to unit length first: the rows scale with the masses and the torque rows with the
        # lever arms, so an absolute threshold would drop real constraints (very unequal or
        # very small masses once made the torque rows look like rank deficiency).
        norms = np.linalg.norm(c, axis=1)
        c = c[norms > 0] / norms[norms > 0, None]
        _, sv, vt = np.linalg.svd(c)
        rank = int(np.sum(sv > 1e-10 * sv.max())) if sv.size else 0
        basis = vt[rank:].T  # [P*D, P*D - rank]
        r = resid[s].ravel()[obs]
        b = basis[obs]
        if b.shape[1]:
            z, *_ = np.linalg.lstsq(b, r, rcond=None)
            r = r - b @ z
        total += float(r @ r)
    n = weight.sum()
    return float(np.sqrt(total / n) * 1000.0) if n else float("nan")


def model_floor_rms_mm(model: Model, positions: np.ndarray, mask: np.ndarray, dt: float):
    """The momentum floor for ``model``'s family, or None where it does not apply: a bond kind
    with external forces (a unary bond) conserves nothing, and free masses make the reachable
    accelerations depend on them (the floor of the file's masses is no floor of the family)."""
    external = [k for k in model.topology.active() if not bonds.get(k).internal]
    if external or (np.asarray(model.layout.index.mass) >= 0).any():
        return None
    if model.layout.gravity_direction is not None:  # a free field: its floor is no floor
        return None
    gravity = np.asarray(model.params.gravity, np.float64)
    return momentum_floor_rms_mm(positions, mask, dt, model.params.mass, gravity)
