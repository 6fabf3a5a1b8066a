"""The genome of a model being built: one piece per owner of genes.

:func:`activebonds.model.build` fills the model file's values into :class:`Params` (``base``)
and, for each free number, the index of its gene into a tree of the same shapes (``index``,
-1 for fixed entries). The pieces here do it owner by owner, in genome order: the masses
(:func:`put_masses`), a free gravity magnitude (:func:`put_gravity`), the kinds' shared
parameters (:func:`put_shared`) and the bonds' own (:func:`put_bonds`, through their forms:
:mod:`activebonds.model.forms`). :class:`Genome` holds the genes and their groups (DESIGN.md
§3: all occurrences of a bond type share one gene per key) as they are made.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from .. import bonds
from .forms import Entry, ScalarForm, form_of
from .genes import Gene, bond_group
from .layout import gravity_bounds, mass_bounds, pick_log
from .params import Params
from .schema import GravityParam, ModelSpec, entry_at
from .values import Param, VectorParam, Weights


def is_free(p: Any) -> bool:
    return isinstance(p, Param | VectorParam | Weights) and not p.fixed


def value_of(p: float | Param | None, default: float = 0.0) -> float:
    if p is None:
        return default
    return p.value if isinstance(p, Param) else float(p)


def shared_value(spec: ModelSpec, par: bonds.Parameter):
    """A shared parameter's entry in its top-level table (None without the table)."""
    return entry_at(spec, par.key)


def takes(bond, par: bonds.Parameter) -> bool:
    """Whether ``bond`` takes the parameter ``par`` (its ``when`` flag, if any, is set)."""
    return not par.when or bool(getattr(bond, par.when))


class Genome:
    """The genes and groups made so far, and the particles of each group."""

    def __init__(self):
        self.genes: list[Gene] = []
        self.bonds: list[list[int]] = []  # per gene, the bonds it sets
        self.gene_of: dict[str, int] = {}
        self.groups: list[str] = []
        self.group_of: dict[str, int] = {}
        self.slots: list[list[int]] = []

    def group(self, name: str, particles=()) -> int:
        """The group ``name`` (made on first use), its slots extended by ``particles``."""
        if name not in self.group_of:
            self.group_of[name] = len(self.groups)
            self.groups.append(name)
            self.slots.append([])
        g = self.group_of[name]
        self.slots[g].extend(particles)
        return g

    def put(self, values, indices, entry: Entry, p, g: int | None, gene: Gene, bounds) -> None:
        """Write ``entry``'s value; if ``p`` is free and ``g`` a group, its gene's index too
        (the gene made on first use: ``bounds(value)`` unless the entry gives them)."""
        values[entry.where] = entry.value
        if g is None or not is_free(p):
            return
        gene = replace(gene, axis=entry.axis, part=entry.part, source=entry.source, group=g)
        name = gene.name
        if name not in self.gene_of:
            lo, hi = bounds(entry.value)
            lo = lo if entry.lower is None else entry.lower
            hi = hi if entry.upper is None else entry.upper
            lo, hi = min(lo, entry.value), max(hi, entry.value)
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise ValueError(
                    f"{name}: value {entry.value} gives no finite search bounds; give min and max"
                )
            self.gene_of[name] = len(self.genes)
            gene = replace(
                gene, lower=lo, upper=hi, log=pick_log(lo, hi, entry.log), value=entry.value
            )
            self.genes.append(gene)
            self.bonds.append([])
        i = self.gene_of[name]
        for b in gene.bonds:
            if b not in self.bonds[i]:
                self.bonds[i].append(b)
        indices[entry.where] = i

    def finished(self) -> tuple[tuple[Gene, ...], tuple[str, ...], np.ndarray]:
        """(genes, group names, group slots [n_groups, S] padded with -1)."""
        genes = tuple(
            replace(g, bonds=tuple(b)) for g, b in zip(self.genes, self.bonds, strict=True)
        )
        width = max([len(s) for s in self.slots] + [1])
        slots = np.full((len(self.groups), width), -1, dtype=np.int32)
        for g, ps in enumerate(self.slots):
            slots[g, : len(ps)] = ps
        return genes, tuple(self.groups), slots


def put_masses(spec: ModelSpec, base: Params, index: Params, genome: Genome) -> float | None:
    """The particles' masses; returns ``total_mass`` less the fixed masses under it.

    With ``total_mass``, a free mass's gene is a positive weight w_i (log-scaled, its file
    value and bounds in kg up to a common scale) and m_i = (total - fixed) * w_i / sum(w)."""
    ratios = spec.total_mass is not None and any(spec.free_masses())
    for i, p in enumerate(spec.particle):
        m = p.mass
        base.mass[i] = value_of(m)
        if is_free(m):
            key, log = ("weight", True) if ratios else ("mass", m.log)
            gene = Gene("mass", key, particle=p.name)
            g = genome.group(gene.group_name, [i])
            entry = Entry(i, m.value, m.min, m.max, log)
            genome.put(base.mass, index.mass, entry, m, g, gene, mass_bounds)
    if not ratios:
        return None
    free = np.asarray(index.mass) >= 0
    rest = float(spec.total_mass) - float(base.mass[~free].sum())
    base.mass[free] = rest * (base.mass[free] / base.mass[free].sum())
    return rest


def put_gravity(spec: ModelSpec, base: Params, index: Params, genome: Genome) -> np.ndarray | None:
    """The uniform field; returns its unit direction when its magnitude is a gene (every
    axis of ``index.gravity`` is that gene, ``base.gravity`` the file's vector)."""
    gp, d = spec.gravity, spec.dimension
    if isinstance(gp, GravityParam):
        direction = np.array(gp.unit(d), np.float64)
        base.gravity[:] = gp.value * direction
    elif gp is not None:
        base.gravity[:] = gp
    if not (isinstance(gp, GravityParam) and is_free(gp)):
        return None
    gene = Gene("gravity", "magnitude")
    g = genome.group(gene.group_name, range(len(spec.particle)))  # acts on every particle
    for ax in range(d):
        entry = Entry(ax, gp.value, gp.min, gp.max, gp.log)
        genome.put(base.gravity, index.gravity, entry, gp, g, gene, gravity_bounds)
    base.gravity[:] = gp.value * direction
    return direction


def put_shared(spec: ModelSpec, base: Params, index: Params, genome: Genome, disable) -> None:
    """A kind's shared parameters (e.g. the drive's frequency): one number of a top-level
    table, copied into every bond that takes it, all copies one gene named by its key."""
    names = {p.name: i for i, p in enumerate(spec.particle)}
    for k in bonds.kinds():
        of_kind = [(bi, b) for bi, b in enumerate(spec.bond) if b.kind == k.name]
        for par in k.shared:
            p = shared_value(spec, par)
            takers = [(pos, bi, b) for pos, (bi, b) in enumerate(of_kind) if takes(b, par)]
            if p is None or not takers:
                continue
            gene = Gene("shared", par.key, kind=k.name, field=par.field)
            g = None
            if k.name not in disable and is_free(p):
                particles = [names[n] for _, _, b in takers for n in b.particles]
                g = genome.group(gene.group_name, particles)
            vals, ids = base.bonds[k.name][par.field], index.bonds[k.name][par.field]
            for pos, bi, _ in takers:
                (entry,) = ScalarForm().entries(par, p, pos, len(of_kind), spec.dimension)
                genome.put(vals, ids, entry, p, g, replace(gene, bonds=(bi,)), par.bounds)


def put_bonds(spec: ModelSpec, base: Params, index: Params, genome: Genome, disable) -> None:
    """Each bond's own parameters, in file order, through their forms; an absent bond's
    ``off`` fields at 0 (no force, never genes)."""
    names = {p.name: i for i, p in enumerate(spec.particle)}
    d = spec.dimension
    counts = {k: sum(b.kind == k for b in spec.bond) for k in bonds.names()}
    counters = dict.fromkeys(counts, 0)
    for bi, b in enumerate(spec.bond):
        kind = bonds.get(b.kind)
        pos = counters[b.kind]
        counters[b.kind] += 1
        g = None
        if b.kind not in disable and not b.absent:
            g = genome.group(bond_group(bi, b.type), [names[n] for n in b.particles])
        values, indices = base.bonds[b.kind], index.bonds[b.kind]
        for par in kind.parameters:
            p = getattr(b, par.key)
            if p is None or not takes(b, par):
                continue
            gene = Gene("bond", par.key, kind=b.kind, bonds=(bi,), type=b.type, field=par.field)
            vals, ids = values[par.field], indices[par.field]
            for entry in form_of(par).entries(par, p, pos, counts[b.kind], d):
                genome.put(vals, ids, entry, p, g, gene, par.bounds)
        if b.absent:
            for f in kind.off:
                values[f][pos] = 0.0
