"""Contact bonds: one particle against a plane (Louchet's "conditional" bond; DESIGN.md §2).

A contact bond acts only while its particle is below the plane ``n . x = h`` (``n`` the
bond's fixed unit ``normal``, pointing out of the ground; ``h`` its ``height``). With the
penetration ``d = h - n . x``, while ``d > 0``:

* normal force ``Fn = max(0, k d - c (n . v))`` along ``n``: a spring-damper that pushes and
  never pulls (the damper cannot hold the particle down when it leaves quickly);
* Coulomb friction ``Ft = -mu Fn vt / sqrt(|vt|^2 + eps^2)``, with ``w = v - s`` the
  velocity relative to the surface (``s`` = ``surface_velocity``, e.g. a treadmill belt) and
  ``vt = w - (n . w) n`` its tangential part; ``eps`` = :data:`FRICTION_EPS` (1e-3 m/s)
  smooths the sign of ``vt`` near rest (below about ``eps`` the friction acts as a viscous
  drag of ``mu Fn / eps``);

and no force otherwise. The forces are external (no momentum floor) and not linear in the
parameters (no exact least squares). Pure JAX without branching on values: the contact is a
``jnp.where`` on ``d > 0`` whose both branches are finite, and the friction's denominator is
at least ``eps``, so neither values nor gradients can turn NaN at the switch or at rest.

Model file::

    [[bond]]
    kind = "contact"
    type = "ground"                     # bonds of one type share their parameters
    particles = ["HFL"]                 # exactly one particle
    normal = [0.0, 0.0, 1.0]            # required; fixed, never searched (see below)
    height = { value = 0.0, min = -0.1, max = 0.1 }      # m, plane offset along the normal
    stiffness = { value = 1e4, min = 1e2, max = 1e6 }    # N/m of penetration (required)
    damping = { value = 50.0, min = 0.0, max = 1e3 }     # N s/m, normal (default 0)
    friction = { value = 0.8, min = 0.0, max = 2.0 }     # Coulomb coefficient (default 0)
    surface_velocity = [0.0, 0.0, 0.0]  # m/s (default zero), fixed or free per axis

``normal`` is a constant vector (form ``"constant"``): D finite numbers, refused when zero,
normalised when loaded (the forces use the unit vector) and written back as the file gave
it. ``stiffness``, ``damping`` and ``friction`` must be >= 0. Default search bounds when a
free parameter gives no min/max: height ``h +- 0.1`` m; stiffness ``k/100 .. 100 k``
(``1e2 .. 1e6`` N/m for 0); damping ``c/100 .. 100 c`` (``0 .. 1e3`` N s/m for 0); friction
``0 .. max(2, 2 mu)``; each surface velocity axis ``s +- 1`` m/s.

Step sizes. Near rest on the surface the smoothed friction is a viscous drag of ``mu Fn / eps``
(about 6000 N s/m for 1 kg pressed by gravity with mu = 0.6): with a (sub)step ``h`` above
``m eps / (mu Fn)`` (~0.2 ms there) a sticking particle's tangential velocity would chatter
within about ``mu Fn h / m`` of the surface's under an explicit kick. The normal spring needs
``h sqrt(k / m)`` well below 2. One step per frame (the paper's one-step cost) keeps the
explicit kick, which from a recorded state is a single step; with substeps > 1 every
substep's kick is linearly implicit in the contact's velocity dependence
(:func:`~activebonds.physics.integrate.kick`), so sticking settles at any substep, and the
start velocity is solved by Newton's method
(:func:`~activebonds.physics.integrate.start_velocity`); the few frames where it stalls at a
kink of this law (a contact starting or ending within the frame) are counted in the fit's
output. Multiple shooting (``fit --cost shooting --substeps 20``) fits contact models without
the one-step cost's bias (tests/test_hopper_recovery.py).
"""

from __future__ import annotations

import jax.numpy as jnp

from .accumulate import accumulate
from .kind import NON_NEGATIVE, BondKind, MujocoForm, Parameter, spread

FRICTION_EPS = 1e-3  # m/s: the tangential speed below which Coulomb friction is smoothed


def forces(params, topology, x, v):
    idx = topology["particles"][:, 0]
    n = params["normal"]  # [N, D], unit vectors (normalised when the model is built)
    xp, vp = x[idx], v[idx]
    depth = params["height"] - jnp.sum(n * xp, axis=-1)
    normal_speed = jnp.sum(n * vp, axis=-1)
    push = jnp.maximum(0.0, params["stiffness"] * depth - params["damping"] * normal_speed)
    fn = jnp.where(depth > 0.0, push, 0.0)
    w = vp - params["surface_velocity"]
    vt = w - jnp.sum(n * w, axis=-1, keepdims=True) * n
    smooth_speed = jnp.sqrt(jnp.sum(vt * vt, axis=-1) + FRICTION_EPS**2)  # >= eps > 0
    f = fn[:, None] * n - (params["friction"] * fn / smooth_speed)[:, None] * vt
    return accumulate(x.shape[0], [(idx, 1, f)])


def _mujoco_refusal(bond) -> str | None:
    """A moving surface (a treadmill belt): MuJoCo's planes do not move."""
    velocity = bond.surface_velocity
    if velocity is None:
        return None
    values = velocity if isinstance(velocity, list) else getattr(velocity, "value", velocity)
    values = values if isinstance(values, list) else [values]
    if not any(float(getattr(v, "value", v)) != 0.0 for v in values):
        return None
    return "contact bonds with a moving surface (surface_velocity: MuJoCo's planes stand still)"


def _height_bounds(v):
    return (v - 0.1, v + 0.1)


def reach(bond, x):
    """[S] True where the particle at ``x`` [S, D] is below the highest plane its height's
    bounds allow (where the contact may push)."""
    import numpy as np

    h = bond.height
    if isinstance(h, int | float) or h.fixed:
        top = float(getattr(h, "value", h))
    else:
        top = h.max if h.max is not None else _height_bounds(h.value)[1]
    n = np.asarray(bond.normal, np.float64)
    n = n / np.linalg.norm(n)
    return np.asarray(x, np.float64) @ n < top


KIND = BondKind(
    name="contact",
    arity=1,
    parameters=(
        Parameter("normal", "normal", None, form="constant", note=" (a list of D numbers)"),
        Parameter("height", "height", 0.0, _height_bounds),
        Parameter("stiffness", "stiffness", None, spread(100, (1e2, 1e6)), check=NON_NEGATIVE),
        Parameter("damping", "damping", 0.0, spread(100, (0.0, 1e3)), check=NON_NEGATIVE),
        Parameter(
            "friction", "friction", 0.0, lambda v: (0.0, max(2.0, 2.0 * v)), check=NON_NEGATIVE
        ),
        Parameter(
            "surface_velocity", "surface_velocity", 0.0, lambda v: (v - 1.0, v + 1.0), form="vector"
        ),
    ),
    forces=forces,
    internal=False,
    what="contacts",
    noun="contact",
    mujoco=MujocoForm("pair", lambda bond: _mujoco_refusal(bond)),
    reach=reach,
    stiff_in_velocity=True,
)
