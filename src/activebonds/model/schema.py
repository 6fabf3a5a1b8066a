"""The model file's schema (DESIGN.md §4), validated with pydantic.

A model file is TOML: top-level ``name``, ``dimension``, optional ``gravity`` (a fixed vector,
or a table ``{ value, min, max, direction }``: a magnitude, free or fixed, along a fixed
direction) and ``total_mass`` (kg: the free masses are then identified as ratios of it),
an optional ``[drive]`` table (``frequency`` in Hz, > 0, fixed or free: the rhythmic drive of
the neurons, whose ``drive_weight`` and ``drive_phase`` need it; an optional ``coupling``
table entrains its phase by the body, :class:`Coupling`, with an optional second signal
``quadrature``, :class:`Quadrature`); ``[[particle]]``
tables and ``[[bond]]`` tables. Every parameter is a number (fixed) or a table
``{ value = .., min = .., max = .., fixed = false, log = .. }``. Vector parameters (``anchor``,
``gravity``) take lists; neural ``weights`` take ``length`` and ``rate`` lists with one entry per
binary bond of the model (in file order; a neuron's own entry is ignored and written as 0).
Constant vectors (a contact bond's ``normal``) are plain lists, never searched: D finite
numbers, not zero (normalised when the model is built, written back as given).

A bond table is checked by its kind's class, made from the kind's declaration
(:mod:`activebonds.bonds`): its flags, its parameters and their rules.
"""

from __future__ import annotations

import functools
import math
from typing import Annotated, Any, Literal

from pydantic import (
    Field,
    StrictBool,
    WrapValidator,
    create_model,
    field_validator,
    model_validator,
)

from .. import bonds
from ..axes import AXES
from .forms import form_of
from .values import FiniteFloat, Param, Scalar, _finite, _Strict, _value_of


class GravityParam(Param):
    """Gravity as a magnitude (m/s^2, fixed or free within [min, max]) along a fixed
    ``direction`` (any non-zero vector, normalised; default minus the last axis). Its one gene
    is ``gravity.magnitude``."""

    direction: list[FiniteFloat] | None = None

    def unit(self, dimension: int) -> list[float]:
        """The normalised direction (minus the last axis when none is given)."""
        if self.direction is None:
            return [0.0] * (dimension - 1) + [-1.0]
        norm = math.sqrt(sum(x * x for x in self.direction))
        return [x / norm for x in self.direction]


GRAVITY_ZERO = 1e-12  # a gravity direction this short is refused as zero


class Quadrature(_Strict):
    """A second signal of an entrained drive, read against sin psi: d psi/dt = 2 pi f -
    gain s cos psi - gain_b s_b sin psi. Its ``signal``, ``particle``/``particles`` and
    ``offset`` as the first's; ``gain`` (rad/s per m, either sign: the second signal may lead
    or lag the first by a quarter stride; gene ``drive.coupling.quadrature.gain``) a number
    or a ``{ value, min, max }`` table. Two signals a quarter period apart, their gains
    times amplitudes equal, pull the phase without making it run unevenly within the
    period (DESIGN.md §2, "Entrained drive")."""

    signal: Literal["height", "length"] = "height"
    particle: str | None = Field(default=None, min_length=1)
    particles: list[str] | None = None
    axis: Literal["X", "Y", "Z", "x", "y", "z"] | None = None
    gain: FiniteFloat | Param
    offset: FiniteFloat = 0.0


class Coupling(_Strict):
    """The entrainment of the drive (DESIGN.md §2, "Entrained drive"): its phase psi is a
    state, d psi/dt = 2 pi f - gain s cos psi, pulled by the body's signal s minus ``offset``
    (m, fixed): with ``signal = "height"`` (the default), the coordinate of ``particle`` along
    ``axis`` (a letter, X, Y or Z; default the last axis, up for the default gravity); with ``signal = "length"``, the distance
    between the two ``particles`` (e.g. a leg bond's length). ``gain`` (rad/s per m, >= 0;
    gene ``drive.coupling.gain``) and ``start_phase`` (psi at the first frame of the window or
    the simulation, rad; gene ``drive.coupling.start_phase`` when free) are numbers or
    ``{ value, min, max }`` tables. An optional ``quadrature`` table adds a second signal
    read against sin psi (:class:`Quadrature`)."""

    signal: Literal["height", "length"] = "height"
    particle: str | None = Field(default=None, min_length=1)
    particles: list[str] | None = None
    axis: Literal["X", "Y", "Z", "x", "y", "z"] | None = None
    gain: FiniteFloat | Param
    offset: FiniteFloat = 0.0
    start_phase: FiniteFloat | Param = 0.0
    quadrature: Quadrature | None = None


class Drive(_Strict):
    """The rhythmic drive (DESIGN.md §2): one phase oscillator sin(psi + phi_b) read by every
    neuron with a ``drive_weight``; ``frequency`` f in Hz (> 0), fixed or free (gene
    ``drive.frequency``). Without ``coupling`` psi = 2 pi f t (a clock); with it psi is a
    state of the model entrained by the body (:class:`Coupling`)."""

    frequency: FiniteFloat | Param
    coupling: Coupling | None = None


def _reads_drive(bond) -> bool:
    """Whether a bond of the model file reads the rhythmic drive (takes its frequency)."""
    if bond.kind not in bonds.drive_kinds():
        return False
    par = next(p for p in bonds.get(bond.kind).shared if p.field == "drive_frequency")
    return not par.when or bool(getattr(bond, par.when, False))


def _check_signal(table, where: str, names: set[str], dimension: int) -> None:
    """A coupling signal's particles: one known name for a height, two distinct known names
    for a length (``where``: the table's dotted key, for the message); a height's axis one
    of the model's."""
    if table.axis is not None and (
        table.signal != "height" or AXES.index(table.axis.upper()) >= dimension
    ):
        raise ValueError(
            f"{where}.axis: a height's axis, one of {', '.join(AXES[:dimension])} (a length has "
            "none)"
        )
    if table.signal == "height":
        if table.particle is None or table.particles is not None:
            raise ValueError(f"{where}.particle: a height signal needs particle = .. (one name)")
        named = [("particle", table.particle)]
    else:
        pair = table.particles
        if table.particle is not None or pair is None or len(set(pair)) != 2:
            raise ValueError(
                f"{where}.particles: a length signal needs particles = [A, B] (two distinct names)"
            )
        named = [("particles", n) for n in pair]
    for key, name in named:
        if name not in names:
            raise ValueError(f"{where}.{key}: unknown particle '{name}'")


def entry_at(spec, key: str):
    """The entry of a dotted key of the model file (``drive.coupling.gain``), None where a
    table on its path is absent."""
    value = spec
    for part in key.split("."):
        value = getattr(value, part, None)
        if value is None:
            return None
    return value


class Particle(_Strict):
    name: str = Field(min_length=1)
    mass: Scalar = 1.0
    marker: str | None = None
    position: list[float] | None = None
    velocity: list[float] | None = None

    @field_validator("mass")
    @classmethod
    def _positive_mass(cls, m: Scalar) -> Scalar:
        value = m.value if isinstance(m, Param) else m
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"mass must be a finite number > 0, got {value}")
        if isinstance(m, Param) and m.min is not None and m.min <= 0:
            raise ValueError("mass min must be > 0")
        return m

    @field_validator("position", "velocity")
    @classmethod
    def _finite_vec(cls, xs: list[float] | None) -> list[float] | None:
        return None if xs is None else [_finite(x) for x in xs]


class BondBase(_Strict):
    """The keys every bond table has; each kind's class (:func:`bond_class`) adds its flags
    and parameters, from the kind's declaration in :mod:`activebonds.bonds`."""

    @property
    def absent(self) -> bool:
        """An optional bond identified as absent: it exerts no force and has no genes."""
        return bool(self.optional) and self.present is False

    kind: str
    particles: list[str]
    type: str | None = None
    optional: StrictBool | None = None  # structure identification decides if it is present
    present: StrictBool | None = None  # an optional bond's decision; false: no force, no genes

    @model_validator(mode="before")
    @classmethod
    def _foreign_keys(cls, data: Any) -> Any:
        """Keys of other kinds: a parameter named as such, a flag only where it is set."""
        if not isinstance(data, dict):
            return data
        kind = data.get("kind")
        data = dict(data)
        for key in list(data):
            if key in cls.model_fields:
                continue
            flag_of = [k.name for k in bonds.kinds() if key in k.flags]
            if flag_of:
                if data[key] is False:  # e.g. 'neural = false' on a unary bond
                    del data[key]
                    continue
                raise ValueError(f"{key}: only {' and '.join(flag_of)} bonds can be {key}")
            if any(key in k.keys for k in bonds.kinds()):
                raise ValueError(f"{key}: not a parameter of a {kind} bond")
        return data

    @model_validator(mode="after")
    def _check_kind(self) -> BondBase:
        kind = bonds.get(self.kind)
        arity = kind.arity
        # Messages start with the field at fault ("field: ..."); the loader adds it to the path.
        if len(self.particles) != arity:
            raise ValueError(
                f"particles: a {self.kind} bond needs {arity} particle name(s), "
                f"got {len(self.particles)}"
            )
        if len(set(self.particles)) != arity:
            raise ValueError(f"particles: a {self.kind} bond needs {arity} distinct particles")
        if self.present is not None and not self.optional:
            raise ValueError("present: only an optional bond has a presence; add optional = true")
        if self.optional and not kind.off:
            can = ", ".join(k.name for k in bonds.kinds() if k.off)
            raise ValueError(
                f"optional: a {self.kind} bond cannot be optional (its forces do not switch "
                f"off with its parameters; kinds that can: {can})"
            )
        if self.optional and getattr(self, "neural", False):
            raise ValueError(
                "optional: a neural bond cannot be optional (structure identification solves "
                "the bonds linear in their parameters; make it a standard bond)"
            )
        for p in kind.parameters:
            if p.when and getattr(self, p.key) is not None and not getattr(self, p.when):
                raise ValueError(f"{p.key}: '{p.key}' needs {p.when} = true")
        for p in kind.parameters:
            if p.default is None and getattr(self, p.key) is None:
                raise ValueError(f"{p.key}: a {self.kind} bond needs {p.key}{p.note}")
        for p in kind.parameters:
            value = form_of(p).number(getattr(self, p.key))
            if p.check and value is not None and not p.check.test(value):
                raise ValueError(f"{p.key}: must be {p.check.text}, got {value}")
        return self


@functools.cache
def bond_class(kind: bonds.BondKind) -> type[BondBase]:
    """The pydantic class of a kind's bond tables: its flags and parameters, all optional."""
    fields: dict[str, Any] = {flag: (bool, False) for flag in kind.flags}
    for p in kind.parameters:
        fields[p.key] = (form_of(p).schema | None, None)
    name = kind.name.title().replace("_", "") + "Bond"
    return create_model(name, __base__=BondBase, **fields)


def _bond(data: Any, handler) -> BondBase:
    """A bond table, validated by its kind's class (errors keep their paths)."""
    if isinstance(data, BondBase):
        return data
    if not isinstance(data, dict):
        raise ValueError("expected a table with kind = .. and particles = [..]")
    if "kind" not in data:
        raise ValueError("kind: required key is missing")
    kind = data["kind"]
    if not isinstance(kind, str) or kind not in bonds.names():
        raise ValueError(f"kind: Input should be {bonds.registry.listing(bonds.names())}")
    return bond_class(bonds.get(kind)).model_validate(data)


Bond = Annotated[Any, WrapValidator(_bond)]


class ModelSpec(_Strict):
    """The whole model file."""

    name: str = "model"
    dimension: Literal[2, 3] = 3
    gravity: list[float] | GravityParam | None = None
    total_mass: FiniteFloat | None = None  # kg; fixes the mass scale when masses are free
    drive: Drive | None = None  # the neurons' rhythmic drive (its frequency)
    particle: list[Particle] = Field(min_length=1)
    bond: list[Bond] = Field(default_factory=list)

    @model_validator(mode="after")
    def _check_references(self) -> ModelSpec:
        d = self.dimension
        self._check_dimension()
        names = [p.name for p in self.particle]
        seen: set[str] = set()
        for i, n in enumerate(names):
            if n in seen:
                raise ValueError(f"particle[{i}].name: duplicate particle name '{n}'")
            seen.add(n)
        followed: dict[str, str] = {}
        for i, p in enumerate(self.particle):
            m = p.marker or p.name
            if m in followed:
                raise ValueError(
                    f"particle[{i}].marker: marker '{m}' is already followed by particle "
                    f"'{followed[m]}'"
                )
            followed[m] = p.name
        if isinstance(self.gravity, GravityParam):
            direction = self.gravity.direction
            if direction is not None and len(direction) != d:
                raise ValueError(
                    f"gravity.direction: expected {d} components, got {len(direction)}"
                )
            if direction is not None and math.sqrt(sum(x * x for x in direction)) <= GRAVITY_ZERO:
                raise ValueError(f"gravity.direction: must be a non-zero vector, got {direction}")
        elif self.gravity is not None:
            if len(self.gravity) != d:
                raise ValueError(f"gravity: expected {d} components, got {len(self.gravity)}")
            for g in self.gravity:
                _finite(g, "gravity")
        self._check_mass_scale()
        self._check_shared()
        self._check_coupling(seen)
        for i, p in enumerate(self.particle):
            for field in ("position", "velocity"):
                vec = getattr(p, field)
                if vec is not None and len(vec) != d:
                    raise ValueError(
                        f"particle[{i}].{field}: expected {d} components, got {len(vec)}"
                    )
        neural = any(getattr(b, "neural", False) for b in self.bond)
        optional = next((i for i, b in enumerate(self.bond) if b.optional), None)
        if neural and optional is not None:
            raise ValueError(
                f"bond[{optional}].optional: a model with neural bonds cannot have optional "
                "bonds (an absent bond would still feed the neurons)"
            )
        counts: dict[str, int] = {}
        for b in self.bond:
            counts[b.kind] = counts.get(b.kind, 0) + 1
        types: dict[str, tuple] = {}
        for i, b in enumerate(self.bond):
            kind = bonds.get(b.kind)
            for name in b.particles:
                if name not in seen:
                    raise ValueError(f"bond[{i}].particles: unknown particle '{name}'")
            for p in kind.parameters:
                value = getattr(b, p.key)
                if value is None:
                    continue
                if p.needs and getattr(self, p.needs) is None:
                    raise ValueError(
                        f"bond[{i}].{p.key}: needs the model's top-level [{p.needs}] table"
                    )
                form_of(p).check(p, value, f"bond[{i}].{p.key}", d, counts[b.kind], b.kind)
            if b.type is not None:
                sig = (b.kind, *(getattr(b, flag) for flag in kind.flags))
                if b.type in types and types[b.type] != sig:
                    flags = "".join(f" and {flag}" for flag in kind.flags)
                    raise ValueError(
                        f"bond[{i}].type: bonds of type '{b.type}' must share kind{flags}"
                    )
                types[b.type] = sig
        return self

    def _vector_lengths(self) -> dict[str, list[int]]:
        """The number of components of each vector the file gives (gravity, the particles'
        positions and velocities, the bonds' vector parameters), by what a message calls it."""
        found: dict[str, list[int]] = {}
        gravity = self.gravity
        if isinstance(gravity, GravityParam):
            gravity = gravity.direction
        if gravity is not None:
            found["gravity"] = [len(gravity)]
        for field in ("position", "velocity"):
            for p in self.particle:
                vec = getattr(p, field)
                if vec is not None:
                    found.setdefault(f"particle {field}", []).append(len(vec))
        for b in self.bond:
            for par in bonds.get(b.kind).parameters:
                value = getattr(b, par.key, None)
                if par.form not in ("vector", "constant") or value is None:
                    continue
                vals = value if isinstance(value, list) else value.value
                found.setdefault(f"{b.kind} {par.key}", []).append(len(vals))
        return found

    def _check_dimension(self) -> None:
        """Refuse a ``dimension`` that every vector of the file disagrees with, all having
        the same other length: the mistake is then the dimension, not the vectors."""
        found = self._vector_lengths()
        lengths = {n for ns in found.values() for n in ns}
        if len(lengths) != 1 or self.dimension in lengths or sum(map(len, found.values())) < 2:
            return  # (one vector alone: it may be the mistake as well as the dimension)
        (n,) = lengths
        names = [
            f"every {k}" if len(v) > 1 else k if k == "gravity" else f"the {k}"
            for k, v in found.items()
        ]
        listed = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"
        raise ValueError(
            f"dimension = {self.dimension} but {listed} have {n} "
            f"components: is dimension right? (dimension = {n} would match them)"
        )

    def _check_coupling(self, names: set[str]) -> None:
        """An entrained drive's signals name particles, and some neural bond reads it."""
        coupling = self.drive.coupling if self.drive is not None else None
        if coupling is None:
            return
        _check_signal(coupling, "drive.coupling", names, self.dimension)
        if coupling.quadrature is not None:
            _check_signal(coupling.quadrature, "drive.coupling.quadrature", names, self.dimension)
        if not any(_reads_drive(b) for b in self.bond):
            raise ValueError(
                "drive.coupling: an entrained drive needs a neural bond or a periodic force to "
                "read it (its frequency, gain and start phase are held by them)"
            )

    def _check_shared(self) -> None:
        """The kinds' shared (model-level) parameters in their top-level tables: the value and
        any bounds pass the parameter's check (the drive's frequency > 0)."""
        for kind in bonds.kinds():
            for p in kind.shared:
                value = entry_at(self, p.key)
                if value is None or p.check is None:
                    continue
                if not p.check.test(_value_of(value)):
                    raise ValueError(f"{p.key}: must be {p.check.text}, got {_value_of(value)}")
                for bound in ("min", "max"):
                    b = getattr(value, bound, None)
                    if b is not None and not p.check.test(b):
                        raise ValueError(f"{p.key}.{bound}: must be {p.check.text}, got {b}")

    def free_masses(self) -> list[bool]:
        """Which particles' masses are free (searched)."""
        return [isinstance(p.mass, Param) and not p.mass.fixed for p in self.particle]

    def mass_scale(self) -> str:
        """What fixes the scale of the identified masses, in words (the run report)."""
        free = self.free_masses()
        if not any(free):
            return "not identified: no free masses"
        if self.total_mass is not None:
            return f"total_mass = {self.total_mass:g} kg"
        name = next(p.name for p, f in zip(self.particle, free, strict=True) if not f)
        return f"particle {name}'s mass (fixed)"

    def _check_mass_scale(self) -> None:
        """Scaling every mass, stiffness, damping and gain by one factor leaves every trajectory
        unchanged: free masses need a fixed one or ``total_mass`` to fix the scale."""
        free = self.free_masses()
        fixed = sum(
            float(p.mass.value if isinstance(p.mass, Param) else p.mass)
            for p, f in zip(self.particle, free, strict=True)
            if not f
        )
        if self.total_mass is None:
            if all(free):
                raise ValueError(
                    "particle: every mass is free, but scaling all masses, stiffnesses, "
                    "dampings and gains by one factor leaves every trajectory unchanged: fix "
                    "one particle's mass or give total_mass (kg)"
                )
            return
        total = self.total_mass
        if not total > 0:
            raise ValueError(f"total_mass: must be > 0 kg, got {total}")
        if any(free) and total <= fixed:
            raise ValueError(
                f"total_mass: must exceed the fixed masses' sum ({fixed:g} kg), got {total:g}"
            )
        if not any(free) and abs(total - fixed) > 1e-9 * total:
            raise ValueError(
                f"total_mass: {total:g} kg differs from the particles' masses' sum ({fixed:g} "
                "kg), and no mass is free"
            )
