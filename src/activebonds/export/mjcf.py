"""A model as MuJoCo MJCF: point masses on slide joints, tendons, joint springs, gravity and
ground contacts.

What maps, exactly (the MuJoCo model's forces are the model's, term for term):

* **particle** -> a body at the particle's initial ``position`` with one slide joint per axis
  (x, y, z; a 2D model lives in the plane z = 0 with slide joints x and y), no rotation, an
  ``inertial`` of the particle's mass and a site at its centre. Each joint's ``ref`` is the
  initial coordinate, so ``qpos`` *is* the world position (particle by particle, axis by
  axis) and ``qpos0`` the initial state; the initial velocities are the keyframe
  ``initial`` (``mj_resetDataKeyframe(model, data, 0)``: MuJoCo starts at rest otherwise).
* **binary bond** (not neural) -> a spatial tendon between the two particles' sites with
  ``stiffness`` = k, ``damping`` = c, ``springlength`` = l0: MuJoCo's tendon force
  ``-k (L - l0) - c Ldot`` along the tendon, ``Ldot`` the relative velocity projected on it,
  is the bond's tension ``k (L - l0) + c Ldot`` pulling the two together.
* **unary bond** (a spring + damper to a fixed anchor ``a``: ``-k (x - a) - c v``) -> the
  particle's slide joints: per axis ``stiffness`` = the sum of its unary bonds' k,
  ``springref`` = their k-weighted mean anchor, ``damping`` = the sum of their c. Not a
  tendon to a world site: a tendon's damper acts along the line only, the unary damper in
  every direction. A site on the world body marks each anchor (no force).
* **gravity** -> ``<option gravity>`` (m g on every body).
* **contact bond** (a particle against a still plane) -> a plane geom per distinct plane
  (``normal``, ``height``; lowered by :data:`SPHERE`), a sphere of radius :data:`SPHERE` on the
  particle's body, and an explicit contact ``pair`` per bond (every geom's ``contype`` and
  ``conaffinity`` 0: nothing else collides). MuJoCo's soft contact with ``solref = (-k / m,
  -c / m)`` (its direct stiffness and damping: a reference acceleration, so per kg of the
  particle) and a constant impedance ``d`` = :data:`IMPEDANCE` (``solimp``) accelerates the
  penetration ``delta`` as ``(1 - d) a0 + (k delta - c v) / m``, ``a0`` the other forces'
  acceleration along the normal: the bond's ``max(0, k d - c n.v)`` but for ``1 - d``
  (measured: its rest depth is ``(1 - d) m g / k``). The friction coefficient is the pair's
  on an elliptic cone (``condim`` 3, 1 without friction), applied by the no-slip solver
  (``noslip_iterations``): Coulomb's friction, where the bond smooths it below 1 mm/s; the
  friction rows' damping in the main solve is :data:`FRICTION_DAMPING`, next to nothing
  (a larger one asks for more friction than the cone holds, and the cone's projection lifts a
  sliding particle). What differs, in docs/howto/export-mujoco.md.
* **integrator**: MuJoCo's ``Euler`` with ``eulerdamp`` disabled is the semi-implicit Euler
  of ``simulate`` (``v += h F / m``, then ``x += h v``, every force explicit); the timestep is
  ``1 / (rate * substeps)``, MuJoCo's default (2 ms) without a rate. Without contacts no
  geoms and contacts disabled: nothing else acts.

Refused (:class:`~activebonds.errors.InputError`, one line naming them; nothing written):
neural bonds (a neuron's tension depends on every other bond's state: no MJCF element),
ternary (flexion) bonds (an energy in the cosine of an angle at three particles), contacts
with a moving surface (``surface_velocity`` != 0, a treadmill belt: MuJoCo's planes do not
move), unary bonds with a moving anchor (``anchor_velocity`` != 0) and any other kind.
Optional bonds identified as absent and bonds of disabled kinds exert no force and are left
out.

Each kind declares its MuJoCo form (:class:`~activebonds.bonds.kind.MujocoForm`: a tendon, a
fixed anchor or none, and which of its bonds are refused); this module names no kind.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import bonds
from ..atomic import output_path, write_text_atomic
from ..data.orientation import AXES
from ..errors import InputError

INERTIA = 1e-6  # kg m^2: the bodies' rotational inertia (no rotational joint: it never acts)
SITE_SIZE = "0.01"  # m, the sites' drawn radius (no physics)
EXPRESSIBLE = (
    "point masses, gravity, binary spring-dampers, fixed unary anchors and contacts with a "
    "still plane"
)
SPHERE = 0.01  # m: a contact particle's sphere (its plane is lowered by as much: no effect)
IMPEDANCE = 0.0001  # MuJoCo's least constraint impedance (mjMINIMP): the softest constraint
MJCF_PAIRS = "contact"  # MJCF's section of explicit contact pairs (MuJoCo's word, not a kind)
NOSLIP_ITERATIONS = 10  # MuJoCo's no-slip solver: Coulomb friction within the cone, exactly
# 1/s, per kg: the friction rows' damping in MuJoCo's main solve, next to nothing, so that it
# never asks for more friction than the cone holds (which lifts a sliding particle): the
# no-slip solver applies the friction, the normal forces fixed
FRICTION_DAMPING = 0.01


def _num(x) -> str:
    return repr(float(x))  # shortest round-trip form


def _vec(xs) -> str:
    return " ".join(_num(x) for x in xs)


def _pad3(xs) -> list[float]:
    """A 2D vector (x, y) -> (x, y, 0); 3D unchanged."""
    return [float(x) for x in xs] + [0.0] * (3 - len(xs))


def _form(kind: str) -> bonds.MujocoForm:
    """The kind's MuJoCo form (an empty one, refusing every bond, when it declares none)."""
    return bonds.get(kind).mujoco or bonds.MujocoForm()


def _refusals(model) -> list[str]:
    """What MuJoCo cannot express, in words with the bonds' indices (empty: all of it can)."""
    found: dict[str, list[int]] = {}
    whys: dict[str, str] = {}
    for i, b in enumerate(model.spec.bond):
        if b.absent or b.kind in model.disabled:
            continue
        form = _form(b.kind)
        if form.element is None:  # the kind: MuJoCo has no element for it
            what = f"{b.kind} bonds"
            whys[what] = form.why
        else:  # this bond of a kind that maps
            what = form.refuse(b)
            if what is None:
                continue
        found.setdefault(what, []).append(i)
    out = []
    for what, ids in found.items():
        listed = ", ".join(f"bond[{i}]" for i in ids[:4]) + (", ..." if len(ids) > 4 else "")
        why = f"; {whys[what]}" if whys.get(what) else ""
        what = what.replace("bonds", "bond", 1) if len(ids) == 1 else what
        out.append(f"{len(ids)} {what} ({listed}{why})")
    return out


def check_exportable(model, source: str = "model") -> None:
    """Raise InputError (one line) naming every bond kind MuJoCo cannot express, or a model
    without an initial state."""
    refused = _refusals(model)
    if refused:
        raise InputError(
            source,
            f"cannot export to MJCF: MuJoCo cannot express {', '.join(refused)}; "
            f"only {EXPRESSIBLE} map",
        )
    unplaced = model.unplaced()
    if unplaced is not None:
        raise InputError(
            source,
            f"cannot export to MJCF: {unplaced}; give each [[particle]] a position = [...] "
            f"(and optionally velocity = [...])",
        )


def to_mjcf(model, rate: float | None = None, substeps: int = 1, source: str = "model") -> str:
    """The model as an MJCF document (a string; pure).

    Args:
        model: a :class:`~activebonds.model.Model` of point masses, gravity, binary (not
            neural) bonds, unary bonds with fixed anchors and contacts with a still plane,
            every particle with a position.
        rate: frame rate in Hz; the MuJoCo timestep is ``1 / (rate * substeps)``, so that
            MuJoCo's semi-implicit Euler steps as ``simulate(model, n, rate,
            substeps=substeps)`` does. ``None``: MuJoCo's default timestep.
        substeps: integration steps per frame.
        source: the model's name in error messages (its file).

    Raises:
        InputError: a bond MuJoCo cannot express (every such kind named in one line), a
            particle without ``position``, a bad rate or substeps.
    """
    if rate is not None and not (np.isfinite(rate) and rate > 0):
        raise InputError("--rate", f"must be a positive number of Hz, got {rate}")
    if not (isinstance(substeps, int | np.integer) and substeps >= 1):
        raise InputError("--substeps", f"must be a whole number >= 1, got {substeps}")
    check_exportable(model, source)
    d = model.dimension
    x0, v0 = model.initial_state()
    masses = np.asarray(model.params.mass, np.float64)
    gravity = _pad3(np.asarray(model.params.gravity, np.float64))
    parts = _Parts.of(model)

    root = ET.Element("mujoco", model=model.name)
    root.append(
        ET.Comment(
            f" exported by activebonds from the model '{model.name}': qpos = world positions "
            f"(particle by particle, axes {AXES[:d].lower()}); initial velocities in keyframe "
            f"'initial' (mj_resetDataKeyframe(model, data, 0)) "
        )
    )
    ET.SubElement(root, "compiler", angle="radian", inertiafromgeom="false")
    _option(root, gravity, rate, substeps, parts.contacts)

    world = ET.SubElement(root, "worldbody")
    planes = _planes(world, parts.contacts)
    for i, anchor in parts.anchors:
        site = ET.SubElement(world, "site", pos=_vec(anchor), size=SITE_SIZE, rgba="1 0 0 1")
        if f"bond{i}_anchor" not in parts.names:  # site names must not clash with the particles'
            site.set("name", f"bond{i}_anchor")
    for p, particle in enumerate(model.spec.particle):
        _body(world, particle.name, p, _pad3(x0[p]), d, masses[p], parts)
    _tendons(root, parts.tendons)
    _pairs(root, parts.contacts, planes, masses, model.spec.particle)

    keyframe = ET.SubElement(root, "keyframe")
    ET.SubElement(
        keyframe,
        "key",
        name="initial",
        time="0",
        qpos=_vec(x0.reshape(-1)),
        qvel=_vec(v0.reshape(-1)),
    )
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="unicode") + "\n"


@dataclass
class _Parts:
    """What the model's bonds become in MJCF: per particle, its unary bonds' summed stiffness,
    k-weighted anchor and damping (its slide joints'); the anchors' world sites, the tendons
    and the contact pairs, each with its bond's index."""

    k_sum: np.ndarray
    ka_sum: np.ndarray
    c_sum: np.ndarray
    anchors: list[tuple[int, list[float]]]  # (bond index, anchor) for the world sites
    tendons: list[tuple[int, str, str, float, float, float]]
    contacts: list[tuple[int, int, np.ndarray, float, float, float, float]]
    names: dict[str, int]  # the particles' indices by name

    @classmethod
    def of(cls, model) -> _Parts:
        d, params = model.dimension, model.params
        n = len(model.spec.particle)
        names = {p.name: i for i, p in enumerate(model.spec.particle)}
        out = cls(np.zeros(n), np.zeros((n, d)), np.zeros(n), [], [], [], names)
        counters: dict[str, int] = {}
        for i, b in enumerate(model.spec.bond):
            pos = counters.get(b.kind, 0)
            counters[b.kind] = pos + 1
            if b.absent or b.kind in model.disabled:
                continue
            values = params.bonds[b.kind]
            element = _form(b.kind).element
            if element == "anchor":
                p = names[b.particles[0]]
                k = float(values["stiffness"][pos])
                anchor = np.asarray(values["anchor"][pos], np.float64)
                out.k_sum[p] += k
                out.ka_sum[p] += k * anchor
                out.c_sum[p] += float(values["damping"][pos])
                out.anchors.append((i, _pad3(anchor)))
            elif element == "pair":
                normal = np.asarray(values["normal"][pos], np.float64)
                out.contacts.append(
                    (
                        i,
                        names[b.particles[0]],
                        normal / np.linalg.norm(normal),
                        float(values["height"][pos]),
                        float(values["stiffness"][pos]),
                        float(values["damping"][pos]),
                        float(values["friction"][pos]),
                    )
                )
            elif element == "tendon":
                out.tendons.append(
                    (
                        i,
                        *b.particles,
                        float(values["stiffness"][pos]),
                        float(values["damping"][pos]),
                        float(values["rest_length"][pos]),
                    )
                )
        return out


def _option(root, gravity, rate, substeps, contacts) -> None:
    """``<option>``: Euler, the gravity, the timestep of ``rate`` and ``substeps``; with
    contacts, Coulomb's cone and the no-slip solver."""
    option = ET.SubElement(root, "option", integrator="Euler", gravity=_vec(gravity))
    if rate is not None:
        option.set("timestep", _num(1.0 / (float(rate) * int(substeps))))
    if contacts:  # Coulomb's cone itself; friction by the no-slip solver
        option.set("cone", "elliptic")
        if any(c[6] > 0 for c in contacts):
            option.set("noslip_iterations", str(NOSLIP_ITERATIONS))
    # eulerdamp off: dampers explicit, as in simulate; no contacts but the explicit pairs.
    if contacts:
        ET.SubElement(option, "flag", eulerdamp="disable")
    else:
        ET.SubElement(option, "flag", eulerdamp="disable", contact="disable")


def _body(world, name: str, p: int, start: list[float], d: int, mass, parts: _Parts) -> None:
    """Particle ``p``'s body at ``start``: a slide joint per axis (its unary bonds' spring and
    damper), its inertial, its site and, where it has contacts, its sphere."""
    body = ET.SubElement(world, "body", name=name, pos=_vec(start))
    for ax in range(d):
        axis = ["0", "0", "0"]
        axis[ax] = "1"
        joint = ET.SubElement(
            body,
            "joint",
            name=f"{name}_{AXES[ax].lower()}",
            type="slide",
            axis=" ".join(axis),
            ref=_num(start[ax]),
        )
        if parts.k_sum[p] > 0:
            joint.set("stiffness", _num(parts.k_sum[p]))
            joint.set("springref", _num(parts.ka_sum[p, ax] / parts.k_sum[p]))
        if parts.c_sum[p] > 0:
            joint.set("damping", _num(parts.c_sum[p]))
    ET.SubElement(body, "inertial", pos="0 0 0", mass=_num(mass), diaginertia=_vec([INERTIA] * 3))
    ET.SubElement(body, "site", name=name, pos="0 0 0", size=SITE_SIZE)
    if any(c[1] == p for c in parts.contacts):
        ET.SubElement(
            body,
            "geom",
            name=f"{name}_sphere",
            type="sphere",
            size=_num(SPHERE),
            contype="0",
            conaffinity="0",
            rgba="0.2 0.6 0.2 1",
        )


def _tendons(root, tendons) -> None:
    """``<tendon>``: a spatial tendon between its two particles' sites per binary bond."""
    if not tendons:
        return
    tendon = ET.SubElement(root, "tendon")
    for i, a, b, k, c, l0 in tendons:
        spatial = ET.SubElement(
            tendon,
            "spatial",
            name=f"bond{i}",
            stiffness=_num(k),
            damping=_num(c),
            springlength=_num(l0),
            width="0.005",
        )
        ET.SubElement(spatial, "site", site=a)
        ET.SubElement(spatial, "site", site=b)


def _pairs(root, contacts, planes: dict, masses, particles) -> None:
    """MJCF's explicit contact pairs: per contact bond, its plane (of ``planes``) against its
    particle's sphere, its stiffness and damping per kg of the particle."""
    if not contacts:
        return
    pairs = ET.SubElement(root, MJCF_PAIRS)
    for i, p, normal, height, k, c, mu in contacts:
        m = float(masses[p])
        pair = ET.SubElement(
            pairs,
            "pair",
            name=f"bond{i}",
            geom1=planes[(tuple(normal), height)],
            geom2=f"{particles[p].name}_sphere",
            condim="3" if mu > 0 else "1",
            friction=_vec([mu, mu, 0.0, 0.0, 0.0]),
            solref=_vec([-k / m, -c / m]),
            solreffriction=_vec([-k / m, -FRICTION_DAMPING]),
            solimp=_vec([IMPEDANCE, IMPEDANCE, 0.001, 0.5, 2.0]),
        )
        pair.set("margin", "0")


def _planes(world, contacts) -> dict:
    """A plane geom per distinct (normal, height) of the contacts, on the world body, lowered
    by the spheres' radius (so that MuJoCo's distance, the sphere's surface to the plane, is
    the contact's ``n . x - height``); {(normal, height): its name}."""
    found: dict = {}
    for _, _, normal, height, *_ in contacts:
        key = (tuple(normal), height)
        if key in found:
            continue
        name = f"ground{len(found)}"
        found[key] = name
        n3 = _pad3(normal)
        ET.SubElement(
            world,
            "geom",
            name=name,
            type="plane",
            size="0 0 1",
            pos=_vec(np.asarray(n3) * (height - SPHERE)),
            zaxis=_vec(n3),
            contype="0",
            conaffinity="0",
            rgba="0.8 0.8 0.8 1",
        )
    return found


def write_mjcf(
    model, path: str | Path, rate: float | None = None, substeps: int = 1, source: str = "model"
) -> Path:
    """Write :func:`to_mjcf` atomically (a temporary sibling, then rename); nothing is written
    when the model is refused."""
    path = output_path(path)
    if not path.parent.exists():
        raise InputError(path, "the folder does not exist")
    text = to_mjcf(model, rate=rate, substeps=substeps, source=source)
    write_text_atomic(path, text)
    return path
