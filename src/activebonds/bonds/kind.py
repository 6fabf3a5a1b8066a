"""What a bond kind declares: its file parameters, its topology and its forces.

A kind is one :class:`BondKind` value, usually in a module of its own (``unary.py``,
``binary.py``, ``ternary.py``) and registered in :mod:`activebonds.bonds.registry`. The model
file's schema, the genome layout, the physics, the least squares, the report and the MuJoCo
export read these declarations; none of them names a kind.

Array conventions: a kind with N bonds in a model of P particles in D dimensions has
``topology["particles"]`` [N, arity] (int32) and one [N] bool array per flag (e.g.
``topology["neural"]``); its parameters are ``{field: array}`` with [N] per scalar, [N, D] per
vector, [N, N] per weights row and [N, D] per constant (unit vector) parameter, and [N] per
shared (model-level) parameter, one copy per bond that takes it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

Bounds = Callable[[float], tuple[float, float]]


@dataclass(frozen=True)
class Check:
    """A rule on a parameter's file value; the message reads '<key>: must be <text>, got v'."""

    test: Callable[[float], bool]
    text: str


NON_NEGATIVE = Check(lambda v: v >= 0, ">= 0")
POSITIVE = Check(lambda v: v > 0, "> 0")
ANGLE = Check(lambda v: 0.0 <= v <= math.pi, "in [0, pi] radians")


def spread(factor: float, zero: tuple[float, float]) -> Bounds:
    """Bounds ``(v / factor, v * factor)`` for a positive file value v, ``zero`` otherwise."""
    return lambda v: (v / factor, v * factor) if v > 0 else zero


@dataclass(frozen=True)
class Parameter:
    """One parameter of a bond kind.

    ``key`` is its name in the model file, ``field`` its array in ``params.bonds[kind]``.
    Forms: ``"scalar"`` (a number or a ``{ value, min, max }`` table; one value per bond),
    ``"vector"`` (one value per axis, like ``anchor``; genes ``key[axis]``) and ``"weights"``
    (one row per bond over the bonds of the same kind, the ``part`` sub-list of a
    ``{ length, rate, min, max }`` table; genes ``key.part[j]``, a bond's own entry unused)
    and ``"constant"`` (a fixed per-bond vector of D finite numbers, never a gene, e.g. a
    contact's ``normal``: refused when zero, stored normalised in ``params.bonds[kind]``,
    written back as the file gave it).

    A *shared* parameter (:attr:`BondKind.shared`) is a model-level number, not a key of the
    bond table: ``key`` is ``"table.name"``, the entry ``name`` of the model file's top-level
    ``[table]`` (e.g. ``"drive.frequency"``), one value for every bond that takes it (its
    ``when`` flag), one gene named ``key`` when free; ``default`` is its value when the model
    has no such table.
    """

    key: str
    field: str
    default: float | None = 0.0  # the value when the file omits it; None: required
    bounds: Bounds = lambda v: (v - 1.0, v + 1.0)  # default search bounds from the file value
    log: bool | None = None  # forced log scaling; None: the file's choice or the bounds' ratio
    check: Check | None = None
    form: Literal["scalar", "vector", "weights", "constant"] = "scalar"
    part: str | None = None  # weights form: "length" or "rate"
    when: str | None = None  # a flag the bond must set to take this parameter (e.g. "neural")
    note: str = ""  # added to the 'needs <key>' message of a required parameter
    needs: str | None = None  # a top-level table the model file must have (e.g. "drive")


# a spring's stiffness and a damper's damping, as the spring kinds declare them (the search
# from 100x below to 100x above the file's value; from 0 to 1e3 or 10 where it is 0)
STIFFNESS = Parameter("stiffness", "stiffness", 0.0, spread(100, (0.0, 1e3)), check=NON_NEGATIVE)
DAMPING = Parameter("damping", "damping", 0.0, spread(100, (0.0, 10.0)), check=NON_NEGATIVE)


@dataclass(frozen=True)
class LinearPart:
    """How a kind enters the exact least squares (:mod:`activebonds.identify.solvers.lsq`).

    ``fields`` are the parameters it solves for; ``switch_off(values, index, topology,
    layout)`` returns the kind's parameters with *every* force of the kind removed (or raises
    ValueError): the fixed terms enter through ``columns`` too, so a switched-off kind
    contributes nothing to the known forces; ``columns(values, index, topology, x, v,
    unknowns)`` adds the displacement of each linear unknown (and of the fixed terms) through
    ``unknowns``."""

    fields: frozenset[str]
    switch_off: Callable
    columns: Callable


@dataclass(frozen=True)
class PopulationForm:
    """A kind's forces for a whole population at once, at fixed recorded states (the ES's
    one-step cost, :mod:`activebonds.identify.search.population_cost`): the same law as
    :attr:`BondKind.forces`, vmapped over individuals and states, to rounding.

    ``prepare(topology, x0, v0, n_particles, dtype, dense_limit)`` computes once what does not
    depend on the genome, from the restart states ``x0, v0`` [S, P, D] (float64 NumPy), in
    ``dtype``; ``dense_limit`` is the largest bonds x particles spread by a dense product.
    ``forces(params, prepared, t0, n_particles, dim)`` gives [S, P, D, N] for N individuals
    (``params`` this kind's arrays, the population first: [N, ...]; ``t0`` [S] the restarts'
    times)."""

    prepare: Callable
    forces: Callable


@dataclass(frozen=True)
class MujocoForm:
    """How the MuJoCo export (:mod:`activebonds.export.mjcf`) writes a kind's bonds.

    ``element``: ``"tendon"`` (a spatial tendon between the bond's two particles, from its
    ``stiffness``, ``damping`` and ``rest_length``), ``"anchor"`` (springs of the particle's
    slide joints to a fixed ``anchor``, from its ``stiffness``, ``damping`` and ``anchor``),
    ``"pair"`` (a contact pair of a sphere on the particle and a plane, from its ``normal``,
    ``height``, ``stiffness``, ``damping`` and ``friction``) or None (MuJoCo cannot express the
    kind: its bonds are refused as '<kind> bonds', ``why`` added to the message). ``refuse(bond)`` names, in words, a bond of the model file (a
    ``[[bond]]`` entry) that MuJoCo cannot express although its kind maps (``"neural
    bonds"``), or returns None."""

    element: Literal["tendon", "anchor", "pair"] | None = None
    refuse: Callable[[object], str | None] = lambda bond: None
    why: str = ""


def _timeless(forces: Callable) -> Callable:
    def timed(params, topology, x, v, t):
        return forces(params, topology, x, v)

    return timed


@dataclass(frozen=True)
class BondKind:
    """A bond kind: ``forces(params, topology, x, v, t) -> [P, D]`` for one individual, with
    ``params`` and ``topology`` this kind's dicts, ``x, v`` [P, D] and ``t`` the time in
    seconds from the first frame of the data window (or of the simulation), a scalar (pure
    JAX). A kind whose forces depend on time says so (``timed=True``) and writes them with
    five arguments; the others write ``forces(params, topology, x, v)`` and are adapted when
    the kind is made. ``shared`` are its model-level parameters (see :class:`Parameter`),
    held in ``params`` beside its own as [N] copies."""

    name: str
    arity: int
    parameters: tuple[Parameter, ...]
    forces: Callable
    flags: tuple[str, ...] = ()  # boolean keys of the bond table, one [N] array each
    internal: bool = True  # forces sum to zero without torque (momentum floor applies)
    what: str = ""  # its parameters in words, for messages ("flexion springs")
    noun: str = ""  # a bond of the kind in words, for parameter labels ("flexion spring");
    # its name when not given
    activity: Callable | None = None  # (params, topology, x, v[, t]) -> [N] neuron activations
    linear: LinearPart | None = None
    population: PopulationForm | None = None  # else vmapped over the population
    timed: bool = False  # forces take the time t as a fifth argument
    shared: tuple[Parameter, ...] = ()  # model-level parameters ("drive.frequency")
    off: tuple[str, ...] = ()  # fields that, all at 0, remove every force of a bond: a kind
    # with them can be optional (``optional = true``); an absent bond has them at 0, no genes
    mujoco: MujocoForm | None = None  # how MuJoCo expresses it; None: it cannot
    # (bond table, x [S, D] of its particle) -> [S] bool: the states where a bond of a kind
    # acting on one particle may exert a force for any value of its parameters within their
    # bounds (structure identification leaves its particle's predictions there out); None:
    # it may act anywhere
    reach: Callable | None = None
    # forces stiff in the velocity for an integrator step (a contact's friction near sticking:
    # a drag of mu Fn / eps); with substeps the integrator takes them implicitly
    stiff_in_velocity: bool = False

    def __post_init__(self):
        if not self.noun:
            object.__setattr__(self, "noun", self.name)
        if not self.timed:
            object.__setattr__(self, "forces", _timeless(self.forces))

    @property
    def keys(self) -> tuple[str, ...]:
        """File keys of its parameters, in declaration order, once each."""
        return tuple(dict.fromkeys(p.key for p in self.parameters))

    @property
    def fields(self) -> tuple[str, ...]:
        """Its arrays in ``params.bonds[kind]``: its parameters', then its shared ones'."""
        return tuple(p.field for p in (*self.parameters, *self.shared))
