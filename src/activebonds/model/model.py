"""A validated model: its spec, topology, genome layout, and the way back to a model file."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import jax
import numpy as np

from .. import bonds
from .layout import Gene, Layout, gravity_bounds, mass_bounds, pick_log
from .params import Params, Topology
from .schema import GravityParam, ModelSpec, Param, VectorParam, Weights


def _value(p: float | Param | None, default: float = 0.0) -> float:
    if p is None:
        return default
    return p.value if isinstance(p, Param) else float(p)


def _is_free(p: Any) -> bool:
    return isinstance(p, Param | VectorParam | Weights) and not p.fixed


@dataclass(frozen=True, eq=False)
class Model:
    """A particle-bond model ready to simulate or identify."""

    spec: ModelSpec
    topology: Topology
    layout: Layout

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


def _shape(p: bonds.Parameter, n: int, d: int) -> tuple[int, ...]:
    return {"scalar": (n,), "vector": (n, d), "weights": (n, n), "constant": (n, d)}[p.form]


def build(spec: ModelSpec, disable=frozenset()) -> Model:
    """Compile a validated spec into topology and genome layout. The bonds of the kinds in
    ``disable`` exert no force and carry no genes (ablations)."""
    disable = frozenset(disable)
    unknown = sorted(disable - set(bonds.names()))
    if unknown:
        raise ValueError(f"disable: unknown bond kind(s) {', '.join(unknown)}")
    names = {p.name: i for i, p in enumerate(spec.particle)}
    d = spec.dimension
    kinds = bonds.kinds()
    of_kind = {k.name: [b for b in spec.bond if b.kind == k.name] for k in kinds}
    topology = Topology(
        n_particles=len(spec.particle),
        dimension=d,
        bonds={
            k.name: {
                "particles": np.array(
                    [[names[n] for n in b.particles] for b in of_kind[k.name]], dtype=np.int32
                ).reshape(-1, k.arity),
                **{
                    flag: np.array([getattr(b, flag) for b in of_kind[k.name]], bool).reshape(-1)
                    for flag in k.flags
                },
            }
            for k in kinds
        },
        disabled=disable,
    )
    base = Params(
        mass=np.zeros(len(spec.particle), np.float64),
        gravity=np.zeros(d, np.float64),
        bonds={
            k.name: {
                p.field: np.full(_shape(p, len(of_kind[k.name]), d), p.default or 0.0, np.float64)
                for p in (*k.parameters, *k.shared)
            }
            for k in kinds
        },
    )
    index = jax.tree_util.tree_map(lambda a: np.full(a.shape, -1, np.int32), base)
    direction = None  # the unit vector of a gravity given as a magnitude
    if isinstance(spec.gravity, GravityParam):
        direction = np.array(spec.gravity.unit(d), np.float64)
        base.gravity[:] = spec.gravity.value * direction
    elif spec.gravity is not None:
        base.gravity[:] = spec.gravity

    genes: list[Gene] = []
    gene_of: dict[tuple, int] = {}
    groups: list[str] = []
    group_of: dict[str, int] = {}
    slots: dict[int, list[int]] = {}

    def group(key: str) -> int:
        if key not in group_of:
            group_of[key] = len(groups)
            groups.append(key)
            slots[group_of[key]] = []
        return group_of[key]

    def put(values, indices, where, bounds, p, g, key, value, lower=None, upper=None, log=None):
        values[where] = value
        if g is None or not _is_free(p):
            return
        if (g, key) not in gene_of:
            lo, hi = bounds(value)
            lo = lo if lower is None else lower
            hi = hi if upper is None else upper
            lo, hi = min(lo, value), max(hi, value)
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise ValueError(
                    f"{groups[g]}.{key}: value {value} gives no finite search bounds; "
                    "give min and max"
                )
            use_log = pick_log(lo, hi, log)
            gene_of[(g, key)] = len(genes)
            genes.append(Gene(f"{groups[g]}.{key}", g, lo, hi, use_log, value))
        indices[where] = gene_of[(g, key)]

    # With total_mass, a free mass's gene is a positive weight w_i (log-scaled, its file value
    # and bounds in kg up to a common scale) and m_i = (total - fixed) * w_i / sum(w).
    ratios = spec.total_mass is not None and any(spec.free_masses())
    for i, p in enumerate(spec.particle):
        m = p.mass
        base.mass[i] = _value(m)
        if _is_free(m):
            g = group(f"mass:{p.name}")
            slots[g].append(i)
            key, log = ("weight", True) if ratios else ("mass", m.log)
            put(base.mass, index.mass, i, mass_bounds, m, g, key, m.value, m.min, m.max, log)
    mass_rest = None
    if ratios:
        free = np.asarray(index.mass) >= 0
        mass_rest = float(spec.total_mass) - float(base.mass[~free].sum())
        base.mass[free] = mass_rest * (base.mass[free] / base.mass[free].sum())

    gravity_direction = None
    if isinstance(spec.gravity, GravityParam) and _is_free(spec.gravity):
        gp = spec.gravity
        g = group("gravity")
        slots[g].extend(range(len(spec.particle)))  # the field acts on every particle
        for ax in range(d):
            put(base.gravity, index.gravity, ax, gravity_bounds, gp, g, "magnitude", gp.value,
                gp.min, gp.max, gp.log)  # fmt: skip
        base.gravity[:] = gp.value * direction
        gravity_direction = direction

    # A kind's shared parameters (e.g. the drive's frequency): one number of a top-level table,
    # copied into every bond that takes it, all copies one gene named by its key.
    for k in kinds:
        for par in k.shared:
            table, key = par.key.split(".", 1)
            p = _shared(spec, par)
            takers = [pos for pos, b in enumerate(of_kind[k.name]) if _takes(b, par)]
            if p is None or not takers:
                continue
            g = None
            if k.name not in disable and _is_free(p):
                g = group(table)
                slots[g].extend(names[n] for pos in takers for n in of_kind[k.name][pos].particles)
            lo = p.min if isinstance(p, Param) else None
            hi = p.max if isinstance(p, Param) else None
            lg = p.log if isinstance(p, Param) and par.log is None else par.log
            vals, ids = base.bonds[k.name][par.field], index.bonds[k.name][par.field]
            for pos in takers:
                put(vals, ids, pos, par.bounds, p, g, key, _value(p), lo, hi, lg)

    counters = {k.name: 0 for k in kinds}
    for bi, b in enumerate(spec.bond):
        kind = bonds.get(b.kind)
        pos = counters[b.kind]
        counters[b.kind] += 1
        g = None
        if b.kind not in disable and not b.absent:
            g = group(f"type:{b.type}" if b.type else f"bond[{bi}]")
            slots[g].extend(names[n] for n in b.particles)
        values, indices = base.bonds[b.kind], index.bonds[b.kind]
        for par in kind.parameters:
            p = getattr(b, par.key)
            if p is None or (par.when and not getattr(b, par.when)):
                continue
            vals, ids = values[par.field], indices[par.field]
            if par.form == "scalar":
                lo = p.min if isinstance(p, Param) else None
                hi = p.max if isinstance(p, Param) else None
                lg = p.log if isinstance(p, Param) and par.log is None else par.log
                put(vals, ids, pos, par.bounds, p, g, par.key, _value(p), lo, hi, lg)
            elif par.form == "vector":
                xs = p if isinstance(p, list) else p.value
                for ax in range(d):
                    lo = hi = None
                    if isinstance(p, VectorParam):
                        lo = p.min[ax] if isinstance(p.min, list) else p.min
                        hi = p.max[ax] if isinstance(p.max, list) else p.max
                    key = f"{par.key}[{ax}]"
                    put(vals, ids, (pos, ax), par.bounds, p, g, key, xs[ax], lo, hi, par.log)
            elif par.form == "constant":  # a fixed vector, never a gene: stored normalised
                vec = np.asarray(p, np.float64)
                vals[pos] = vec / np.linalg.norm(vec)
            else:  # weights: a row over the bonds of this kind, the bond's own entry unused
                n = len(of_kind[b.kind])
                xs = getattr(p, par.part)
                xs = xs if isinstance(xs, list) else [xs] * n
                for j in range(n):
                    if j == pos:
                        continue
                    key = f"{par.key}.{par.part}[{j}]"
                    put(vals, ids, (pos, j), par.bounds, p, g, key, xs[j], p.min, p.max, par.log)
        if b.absent:  # no force: the fields that switch it off at 0 (never genes here)
            for f in kind.off:
                values[f][pos] = 0.0

    width = max([len(s) for s in slots.values()] + [1])
    group_slots = np.full((len(groups), width), -1, dtype=np.int32)
    for g, ps in slots.items():
        group_slots[g, : len(ps)] = ps
    layout = Layout(
        genes=tuple(genes),
        groups=tuple(groups),
        group_slots=group_slots,
        base=base,
        index=index,
        gravity_direction=gravity_direction,
        mass_rest=mass_rest,
    )
    return Model(spec=spec, topology=topology, layout=layout)


def _shared(spec: ModelSpec, par: bonds.Parameter):
    """A shared parameter's entry in its top-level table (None without the table)."""
    table, key = par.key.split(".", 1)
    return getattr(getattr(spec, table, None), key, None)


def _takes(bond, par: bonds.Parameter) -> bool:
    return not par.when or bool(getattr(bond, par.when))


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

    def setp(p, v):
        if isinstance(p, Param):
            v = min(max(v, p.min if p.min is not None else v), p.max if p.max is not None else v)
            return p.model_copy(update={"value": float(v)})
        if p is None:
            return None
        return float(v)

    masses = [setp(p.mass, params.mass[i]) for i, p in enumerate(spec.particle)]
    if spec.total_mass is not None and any(spec.free_masses()):
        masses = _ratio_masses(spec, np.asarray(params.mass, np.float64))
    particles = [p.model_copy(update={"mass": masses[i]}) for i, p in enumerate(spec.particle)]
    update_spec: dict[str, Any] = {}
    if isinstance(spec.gravity, GravityParam):
        unit = np.array(spec.gravity.unit(spec.dimension))
        update_spec["gravity"] = setp(spec.gravity, float(np.dot(params.gravity, unit)))
    for kind in bonds.kinds():  # shared parameters: the value of the first bond taking it
        if kind.name in keep or kind.name not in params.bonds:
            continue
        for par in kind.shared:
            table, key = par.key.split(".", 1)
            p = _shared(spec, par)
            takers = [_takes(b, par) for b in spec.bond if b.kind == kind.name]
            if p is None or not any(takers):
                continue
            value = float(np.asarray(params.bonds[kind.name][par.field])[takers.index(True)])
            current = update_spec.get(table, getattr(spec, table))
            update_spec[table] = current.model_copy(update={key: setp(p, value)})
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
            p = getattr(b, par.key)
            if p is None or (par.when and not getattr(b, par.when)):
                continue
            row = values[par.field][pos]
            if par.form == "constant":  # never a gene: written back as the file gave it
                continue
            if par.form == "scalar":
                update[par.key] = setp(p, row)
            elif par.form == "vector":
                xs = [float(x) for x in row]
                update[par.key] = (
                    p.model_copy(update={"value": xs}) if isinstance(p, VectorParam) else xs
                )
            else:
                xs = [0.0 if j == pos else float(x) for j, x in enumerate(row)]
                parts = update.setdefault(par.key, {})
                parts[par.part] = [min(max(x, p.min), p.max) for x in xs]
        for key, value in update.items():
            if isinstance(value, dict):  # the weights table's rows
                update[key] = getattr(b, key).model_copy(update=value)
        out.append(b.model_copy(update=update))
    return spec.model_copy(update={"particle": particles, "bond": out, **update_spec})


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
