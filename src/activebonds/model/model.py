"""A validated model: its spec, topology, genome layout, and the way back to a model file."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import jax
import numpy as np

from .. import bonds
from ..axes import AXES
from .forms import form_of, set_value
from .genome import Genome, put_bonds, put_gravity, put_masses, put_shared, shared_value, takes
from .layout import Layout
from .params import Coupling, Params, Signal, Topology
from .schema import GravityParam, ModelSpec


@dataclass(frozen=True, eq=False)
class Model:
    """A particle-bond model ready to simulate or identify."""

    spec: ModelSpec
    topology: Topology
    layout: Layout

    def __repr__(self) -> str:
        """One line for notebooks: particles, bonds by kind and free parameters, no arrays."""
        absent = sum(b.absent for b in self.spec.bond)
        listed = ", ".join(f"{n} {k}" for k, n in self.bond_counts().items()) or "no bonds"
        if absent:
            listed += f" ({absent} absent)"
        return (
            f"Model({self.name!r}, {self.dimension}D, {len(self.spec.particle)} particles, "
            f"bonds: {listed}, {self.layout.n_genes} free parameters)"
        )

    def _repr_html_(self) -> str:
        """A small table for notebooks: particles, bonds by kind, free parameters."""
        from ..notebook import html_table, names, number

        absent = sum(b.absent for b in self.spec.bond)
        bonds = ", ".join(f"{n} {k}" for k, n in self.bond_counts().items()) or "none"
        rows = [
            ("name", self.name),
            ("dimension", f"{self.dimension}D"),
            ("particles", f"{len(self.spec.particle)}: {names(self.particle_names)}"),
            ("bonds", bonds + (f" ({absent} optional, absent)" if absent else "")),
            ("free parameters", self.layout.n_genes),
        ]
        masses = [p.mass for p in self.spec.particle if isinstance(p.mass, int | float)]
        if self.spec.total_mass is not None:
            rows.append(("total mass", number(self.spec.total_mass, "kg")))
        elif len(masses) == len(self.spec.particle):
            rows.append(("total mass", number(sum(masses), "kg")))
        gravity = self.spec.gravity
        if gravity is not None:
            fixed = isinstance(gravity, list)
            rows.append(("gravity", str(gravity) if fixed else "a parameter"))
        return html_table(f"Model {self.name!r}", rows)

    def bond_counts(self) -> dict[str, int]:
        """The present bonds by kind, in the file's order of first appearance."""
        from collections import Counter

        return dict(Counter(b.kind for b in self.spec.bond if not b.absent))

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def dimension(self) -> int:
        return self.spec.dimension

    @property
    def particle_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.spec.particle)

    @property
    def markers(self) -> tuple[str, ...]:
        return tuple(p.marker or p.name for p in self.spec.particle)

    @property
    def disabled(self) -> frozenset[str]:
        return self.topology.disabled

    @property
    def params(self) -> Params:
        """The model file's values."""
        return self.layout.base

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        d = self.dimension
        x = np.array([p.position or [0.0] * d for p in self.spec.particle], dtype=np.float64)
        v = np.array([p.velocity or [0.0] * d for p in self.spec.particle], dtype=np.float64)
        return x, v

    def unplaced(self) -> str | None:
        """Which particles have no ``position`` (None if every one has), in words: "2 of 3
        particles have no position ('A', 'B')"."""
        missing = [p.name for p in self.spec.particle if p.position is None]
        if not missing:
            return None
        shown = ", ".join(f"'{n}'" for n in missing[:5]) + (" ..." if len(missing) > 5 else "")
        return f"{len(missing)} of {len(self.spec.particle)} particles have no position ({shown})"

    def with_genome(self, genome: np.ndarray) -> Model:
        """The model with its free parameters set from a genome (search space)."""
        return build(with_values(self, self.layout.natural(genome)), disable=self.disabled)

    def without(self, kinds) -> Model:
        """The model with the bonds of ``kinds`` switched off (no force, no genes); writing it
        back keeps their file values. ``Model.without(set())`` switches every kind on again."""
        return build(self.spec, disable=kinds)


def build(spec: ModelSpec, disable=frozenset()) -> Model:
    """Compile a validated spec into topology and genome layout. The bonds of the kinds in
    ``disable`` exert no force and carry no genes (ablations)."""
    disable = frozenset(disable)
    unknown = sorted(disable - set(bonds.names()))
    if unknown:
        raise ValueError(f"disable: unknown bond kind(s) {', '.join(unknown)}")
    topology = _topology(spec, disable)
    base = _file_params(spec)
    index = jax.tree_util.tree_map(lambda a: np.full(a.shape, -1, np.int32), base)
    genome = Genome()
    mass_rest = put_masses(spec, base, index, genome)
    gravity_direction = put_gravity(spec, base, index, genome)
    put_shared(spec, base, index, genome, disable)
    put_bonds(spec, base, index, genome, disable)
    genes, groups, group_slots = genome.finished()
    layout = Layout(
        genes=genes,
        groups=groups,
        group_slots=group_slots,
        base=base,
        index=index,
        gravity_direction=gravity_direction,
        mass_rest=mass_rest,
    )
    return Model(spec=spec, topology=topology, layout=layout)


def _topology(spec: ModelSpec, disable: frozenset[str]) -> Topology:
    names = {p.name: i for i, p in enumerate(spec.particle)}
    arrays = {}
    for k in bonds.kinds():
        of_kind = [b for b in spec.bond if b.kind == k.name]
        particles = [[names[n] for n in b.particles] for b in of_kind]
        arrays[k.name] = {
            "particles": np.array(particles, dtype=np.int32).reshape(-1, k.arity),
            **{f: np.array([getattr(b, f) for b in of_kind], bool).reshape(-1) for f in k.flags},
        }
    return Topology(
        n_particles=len(spec.particle),
        dimension=spec.dimension,
        bonds=arrays,
        disabled=disable,
        drive=_coupling(spec, names, arrays, disable),
    )


def _coupling(spec: ModelSpec, names, arrays, disable) -> Coupling | None:
    """The static part of an entrained drive (None without one, or with the kind that holds
    the drive disabled: no neuron reads it then)."""
    coupling = spec.drive.coupling if spec.drive is not None else None
    if coupling is None:
        return None
    for kind in bonds.drive_kinds():  # the first kind, in order, with a bond that reads it
        if kind in disable:
            continue
        par = next(p for p in bonds.get(kind).shared if p.field == "drive_frequency")
        readers = [takes(b, par) for b in spec.bond if b.kind == kind]
        if any(readers):
            first = _signal(coupling, names, spec.dimension)
            second = coupling.quadrature
            return Coupling(
                *first,
                readers.index(True),
                kind,
                None if second is None else _signal(second, names, spec.dimension),
            )
    return None


def _signal(table, names, dimension: int) -> Signal:
    """A coupling signal's static part: its particles, the height's axis (the table's, else
    the last), its offset."""
    which = [table.particle] if table.signal == "height" else table.particles
    axis = dimension - 1 if table.axis is None else AXES.index(table.axis.upper())
    return Signal(tuple(names[n] for n in which), axis, float(table.offset))


def _file_params(spec: ModelSpec) -> Params:
    """Zero masses and field, every bond parameter at its default (filled in by the pieces)."""
    d = spec.dimension
    arrays = {}
    for k in bonds.kinds():
        n = sum(b.kind == k.name for b in spec.bond)
        arrays[k.name] = {
            p.field: np.full(form_of(p).shape(n, d), p.default or 0.0, np.float64)
            for p in (*k.parameters, *k.shared)
        }
    return Params(
        mass=np.zeros(len(spec.particle), np.float64), gravity=np.zeros(d, np.float64), bonds=arrays
    )


def with_values(model: Model, values: np.ndarray) -> ModelSpec:
    """A spec equal to the model's, with every free parameter set to ``values`` (natural units)."""
    layout = model.layout
    values = np.concatenate([np.asarray(values, dtype=np.float64).reshape(-1), [0.0]])

    def leaf(b, i):
        i = np.asarray(i)
        return np.where(i >= 0, values[np.maximum(i, 0)], b) if i.size else b

    params = layout.derive(jax.tree_util.tree_map(leaf, layout.base, layout.index), np)
    return spec_with_params(model.spec, params, keep=model.disabled)


def spec_with_params(spec: ModelSpec, params: Params, keep=frozenset()) -> ModelSpec:
    """Write numbers back into a spec, keeping which parameters are free and their bounds.
    The bonds of the kinds in ``keep`` keep their file values."""
    masses = [set_value(p.mass, params.mass[i]) for i, p in enumerate(spec.particle)]
    if spec.total_mass is not None and any(spec.free_masses()):
        masses = _ratio_masses(spec, np.asarray(params.mass, np.float64))
    particles = [p.model_copy(update={"mass": masses[i]}) for i, p in enumerate(spec.particle)]
    update_spec: dict[str, Any] = {}
    if isinstance(spec.gravity, GravityParam):
        unit = np.array(spec.gravity.unit(spec.dimension))
        update_spec["gravity"] = set_value(spec.gravity, float(np.dot(params.gravity, unit)))
    for kind in bonds.kinds():  # shared parameters: the value of the first bond taking it
        if kind.name in keep or kind.name not in params.bonds:
            continue
        for par in kind.shared:
            table, key = par.key.split(".", 1)
            p = shared_value(spec, par)
            takers = [takes(b, par) for b in spec.bond if b.kind == kind.name]
            if p is None or not any(takers):
                continue
            value = float(np.asarray(params.bonds[kind.name][par.field])[takers.index(True)])
            current = update_spec.get(table, getattr(spec, table))
            update_spec[table] = _with_entry(current, key, set_value(p, value))
    counters: dict[str, int] = {}
    out = []
    for b in spec.bond:
        pos = counters.get(b.kind, 0)
        counters[b.kind] = pos + 1
        if b.kind in keep or b.absent:
            out.append(b)
            continue
        values = params.bonds[b.kind]
        update: dict[str, Any] = {}
        for par in bonds.get(b.kind).parameters:
            if getattr(b, par.key) is None or not takes(b, par):
                continue
            current = update.get(par.key, getattr(b, par.key))
            update[par.key] = form_of(par).write(par, current, values[par.field][pos], pos)
        out.append(b.model_copy(update=update))
    return spec.model_copy(update={"particle": particles, "bond": out, **update_spec})


def _with_entry(table, key: str, value):
    """A copy of a (frozen) table with its entry at the dotted ``key`` replaced."""
    head, _, rest = key.partition(".")
    if not rest:
        return table.model_copy(update={head: value})
    return table.model_copy(update={head: _with_entry(getattr(table, head), rest, value)})


def _ratio_masses(spec: ModelSpec, mass: np.ndarray) -> list:
    """The particles' masses written back under ``total_mass``: the free ones at their values
    in kg, unclamped (they sum to the total), with any file bounds rescaled by one common
    factor s, as close to 1 as keeps every value inside (the weights' box is defined up to a
    scale, so the same models are searched); widened only where no common factor fits."""
    free = spec.free_masses()
    s_lo, s_hi = 0.0, np.inf
    for p, f, m in zip(spec.particle, free, mass, strict=True):
        if f and p.mass.max is not None:
            s_lo = max(s_lo, m / p.mass.max)
        if f and p.mass.min is not None:
            s_hi = min(s_hi, m / p.mass.min)
    s = min(max(1.0, s_lo), s_hi) if s_lo <= s_hi else float(np.sqrt(s_lo * s_hi))
    out = []
    for p, f, m in zip(spec.particle, free, mass, strict=True):
        if not f:
            out.append(p.mass)
            continue
        lo = None if p.mass.min is None else min(p.mass.min * s, float(m))
        hi = None if p.mass.max is None else max(p.mass.max * s, float(m))
        out.append(p.mass.model_copy(update={"value": float(m), "min": lo, "max": hi}))
    return out
