"""Free parameters as people read them, and which sit at or near their search bounds.

A gene's ``name`` (:class:`~activebonds.model.layout.Gene`) is a machine key: it is stored in
checkpoints, ``uncertainty.json``/``.csv``, sweep summaries and ``baselines --json``, and
never changes. What is *shown* is :func:`parameter_label`, which names a bond by its kind and
particles (or its type) instead of its index in the model file::

    bond[0].stiffness            ->  spring A-B stiffness
    bond[2].weights.length[1]    ->  neural mouth-foot length weight from upper_leg-foot
    bond[3].anchor[2]            ->  unary spring A anchor z
    type:neck.damping            ->  spring type neck damping
    mass:Head.mass               ->  particle Head mass
    mass:Head.weight             ->  particle Head mass weight (under total_mass)
    drive.frequency              ->  drive frequency

A bond's kind word is ``neural`` for a mechanical-neural bond, else its kind's noun
(:attr:`~activebonds.bonds.kind.BondKind.noun`): ``spring`` for any other binary
(viscoelastic) bond, ``unary spring``, ``flexion spring`` or ``contact``; two bonds with the
same word and particles add their index, ``#i``, to tell them apart.

**At or near a bound** (:func:`at_bound`): a fitted value within :data:`NEAR_BOUND` (1 %) of
its gene's search range from ``min`` or ``max``, measured where the search moves: in log
space for log-scaled genes (``log(value)`` within 1 % of ``log(max) - log(min)``), linearly
otherwise. Such a value is where the search stopped, not necessarily where the data want it:
widen the bound and fit again. The bounds are those searched, the *input* model's (a fitted
model file written without ``min``/``max`` derives new bounds around its fitted values).
Free masses under ``total_mass`` are searched as weights ``w_i`` whose common scale changes
nothing (``m_i = rest w_i / sum(w)``): what the bounds constrain is their *ratios*, ``m_i /
m_j`` within ``[min_i / max_j, max_i / min_j]``. They are shown as masses in kg, with their
bounds in kg (the weights' bounds times one common factor, the one ``best_model.toml`` writes:
:func:`mass_rows`), and flagged like every parameter where a ratio is within 1 % of its log
range from a bound (``near max`` for the numerator, ``near min`` for the denominator).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .. import bonds
from ..axes import AXES
from .forms import form_of
from .genes import Gene, bond_group
from .model import Model
from .schema import ModelSpec

NEAR_BOUND = 0.01  # share of the search range (log range for log genes) that is "near"


# ----------------------------------------------------------------------------- names


def _word(bond) -> str:
    if getattr(bond, "neural", False):
        return "neural"
    return bonds.get(bond.kind).noun if bond.kind in bonds.names() else bond.kind


def bond_label(spec: ModelSpec, i: int) -> str:
    """``spring A-B``: bond ``i``'s kind word and particles (``#i`` added when another bond
    has the same)."""
    b = spec.bond[i]
    text = f"{_word(b)} {'-'.join(b.particles)}"
    twins = [
        j
        for j, other in enumerate(spec.bond)
        if _word(other) == _word(b) and other.particles == b.particles
    ]
    return f"{text} #{i}" if len(twins) > 1 else text


def _source_label(spec: ModelSpec, kind: str, position: int) -> str:
    """The particles of the ``position``-th bond of ``kind`` (a weight's input bond)."""
    of_kind = [j for j, b in enumerate(spec.bond) if b.kind == kind]
    if not 0 <= position < len(of_kind):
        return f"bond {position}"
    j = of_kind[position]
    text = "-".join(spec.bond[j].particles)
    return f"{text} #{j}" if bond_label(spec, j).endswith(f" #{j}") else text


def _type_label(spec: ModelSpec, type: str) -> str:
    """``spring type neck``: the kind word of the type's first bond and the type."""
    b = next(b for b in spec.bond if b.type == type)
    return f"{_word(b)} type {type}"


class _Words:
    """The labels of one spec's genes, each bond's words worked out once."""

    def __init__(self, spec: ModelSpec):
        self.spec = spec
        self.known: dict[tuple, str] = {}

    def _head(self, gene: Gene) -> str:
        key = ("type", gene.type) if gene.type else ("bond", gene.bonds[0])
        if key not in self.known:
            spec = self.spec
            self.known[key] = (
                _type_label(spec, gene.type) if gene.type else bond_label(spec, gene.bonds[0])
            )
        return self.known[key]

    def _source(self, kind: str, position: int) -> str:
        key = ("source", kind, position)
        if key not in self.known:
            self.known[key] = _source_label(self.spec, kind, position)
        return self.known[key]

    def label(self, gene: Gene) -> str:
        """``spring A-B stiffness``, ``unary spring C anchor z``, ``neural B-C length weight
        from A-B``, ``particle A mass``, ``drive frequency``: from the gene's fields."""
        if gene.owner == "mass":
            return f"particle {gene.particle} {'mass weight' if gene.key == 'weight' else gene.key}"
        if gene.owner == "gravity":
            return f"gravity {gene.key}"
        if gene.owner == "shared":
            return " ".join(gene.key.split(".", 1))  # its top-level table and entry
        if gene.part is not None:
            words = f"{gene.part} weight from {self._source(gene.kind, gene.source)}"
        elif gene.axis is not None:
            axis = AXES[gene.axis].lower() if gene.axis < len(AXES) else gene.axis
            words = f"{gene.key} {axis}"
        else:
            words = gene.key
        return f"{self._head(gene)} {words}"


def _named(spec: ModelSpec) -> dict[str, Gene | str]:
    """Every gene a model with ``spec`` can have, by name (as if every parameter were free,
    and every kind's shared ones), and the labels of its groups and of its bonds' parameter
    tables (``bond[2]``, ``type:neck``, ``mass:A``, ``bond[1].weights``)."""
    out: dict[str, Gene | str] = {}
    for p in spec.particle:
        out[f"mass:{p.name}"] = f"particle {p.name}"
        for key in ("mass", "weight"):
            gene = Gene("mass", key, particle=p.name)
            out[gene.name] = gene
    gene = Gene("gravity", "magnitude")
    out[gene.name] = gene
    for kind in bonds.kinds():
        for par in kind.shared:
            gene = Gene("shared", par.key, kind=kind.name, field=par.field)
            out[gene.name] = gene
    counts = {k: sum(b.kind == k for b in spec.bond) for k in bonds.names()}
    types: set[str] = set()
    for i, b in enumerate(spec.bond):
        owners = [None]  # the bond itself, and its type the first time it is seen
        if b.type is not None and b.type not in types:
            types.add(b.type)
            owners.append(b.type)
        for t in owners:
            group = bond_group(i, t)
            out[group] = _type_label(spec, t) if t else bond_label(spec, i)
            for par in bonds.get(b.kind).parameters:
                out[f"{group}.{par.key}"] = f"{out[group]} {par.key}"
                for fields in form_of(par).genes(par, counts[b.kind], spec.dimension):
                    gene = Gene("bond", par.key, b.kind, (i,), t, field=par.field, **fields)
                    out[gene.name] = gene
    return out


def labeller(spec: ModelSpec) -> Callable[[str], str]:
    """``name -> label`` for the genes (and gene groups) of a model with ``spec``, as
    :func:`parameter_label`; made once to label many names."""
    named, words = _named(spec), _Words(spec)

    def label(name: str) -> str:
        entry = named.get(name, name)
        return words.label(entry) if isinstance(entry, Gene) else entry

    return label


def parameter_label(spec: ModelSpec, name: str) -> str:
    """The readable name of the gene (or gene group) ``name`` of a model with ``spec``; a
    name it does not know is returned unchanged."""
    return labeller(spec)(name)


def parameter_labels(model: Model) -> list[str]:
    """The readable name of each gene of ``model``, in genome order (from its fields)."""
    words = _Words(model.spec)
    return [words.label(g) for g in model.layout.genes]


# ----------------------------------------------------------------------------- bounds


def bound_position(gene: Gene, value: float) -> float:
    """Where ``value`` sits in ``gene``'s search range: 0 at ``min``, 1 at ``max`` (log space
    for a log-scaled gene; outside [0, 1] beyond the bounds); NaN for an empty range."""
    return _position(float(gene.lower), float(gene.upper), bool(gene.log), float(value))


def _position(lo: float, hi: float, log: bool, v: float) -> float:
    if log:
        if lo <= 0 or hi <= 0:
            return float("nan")
        lo, hi = math.log(lo), math.log(hi)
        v = math.log(v) if v > 0 else -math.inf
    if not (hi > lo) or not math.isfinite(hi - lo):
        return float("nan")
    return (v - lo) / (hi - lo)


def is_mass_weight(gene: Gene) -> bool:
    """A free mass under ``total_mass``: a weight whose common scale changes nothing."""
    return gene.owner == "mass" and gene.key == "weight"


def at_bound(gene: Gene, value: float, share: float = NEAR_BOUND) -> str | None:
    """``"min"`` or ``"max"`` when ``value`` is within ``share`` of ``gene``'s search range
    from that bound (or beyond it), else None (also for an empty range and mass weights)."""
    if is_mass_weight(gene):
        return None
    pos = bound_position(gene, value)
    if math.isnan(pos):
        return None
    if pos < share:
        return "min"
    if pos > 1.0 - share:
        return "max"
    return None


@dataclass(frozen=True)
class ParameterRow:
    """One free parameter as shown: readable name, machine key, fitted value, search bounds
    and whether it is at or near one of them."""

    key: str  # the gene's name (machine key)
    name: str  # readable (parameter_label)
    value: float  # natural units
    lower: float  # search bounds, natural units
    upper: float
    log: bool  # searched in log space
    bound: str | None  # "min" or "max": within NEAR_BOUND of it; None otherwise
    unit: str = ""  # "kg" for a mass under total_mass

    def bound_text(self) -> str:
        """``near max 1000``-style words for a flagged row, "" otherwise."""
        if self.bound is None:
            return ""
        limit = self.lower if self.bound == "min" else self.upper
        return f"near {self.bound} {limit:.6g}" + (f" {self.unit}" if self.unit else "")

    @property
    def position(self) -> float:
        """Where the value sits in the row's bounds: 0 at ``lower``, 1 at ``upper`` (log
        space for a log row), NaN for an empty range."""
        return _position(self.lower, self.upper, self.log, self.value)


def parameter_rows(
    model: Model,
    values: Sequence[float] | np.ndarray | None = None,
    *,
    bounds: Model | None = None,
    share: float = NEAR_BOUND,
) -> list[ParameterRow]:
    """Every free parameter of ``model`` as a :class:`ParameterRow`.

    ``values``: the fitted values in natural units, in genome order (default: the values of
    ``model``'s own genes, e.g. a best model read from its file). ``bounds``: the model whose
    genes hold the search bounds (default ``model``; give the input model of a fit, whose
    bounds were searched), matched by gene name."""
    genes = model.layout.genes
    vals = [g.value for g in genes] if values is None else [float(v) for v in values]
    searched = {g.name: g for g in (bounds or model).layout.genes}
    words = _Words(model.spec)
    rest = (bounds or model).layout.mass_rest
    kg = mass_rows(genes, vals, searched, rest, share) if rest is not None else {}
    rows = []
    for i, (g, v) in enumerate(zip(genes, vals, strict=True)):
        b = searched.get(g.name, g)
        if i in kg:
            rows.append(kg[i])
            continue
        rows.append(
            ParameterRow(
                key=g.name,
                name=words.label(g),
                value=float(v),
                lower=float(b.lower),
                upper=float(b.upper),
                log=bool(b.log),
                bound=at_bound(b, v, share),
            )
        )
    return rows


def mass_rows(
    genes: Sequence[Gene], values: Sequence[float], searched: dict, rest: float, share: float
) -> dict[int, ParameterRow]:
    """The rows of the free masses under ``total_mass`` (genes that are weights, by genome
    index): each mass in kg, ``rest w_i / sum(w)`` (whatever the weights' common scale), its
    bounds in kg, the weights' times the common factor nearest 1 that keeps every mass inside
    (as ``best_model.toml`` writes them), and flagged where a mass ratio is within ``share``
    of its log range from a bound."""
    idx = [i for i, g in enumerate(genes) if is_mass_weight(g)]
    if not idx:
        return {}
    w = np.array([float(values[i]) for i in idx], np.float64)
    bs = [searched.get(genes[i].name, genes[i]) for i in idx]
    lo = np.array([float(b.lower) for b in bs])
    hi = np.array([float(b.upper) for b in bs])
    if not (np.all(w > 0) and np.all(lo > 0) and np.all(hi > lo)):
        return {}
    m = rest * w / w.sum()
    s_lo, s_hi = float(np.max(m / hi)), float(np.min(m / lo))
    scale = min(max(1.0, s_lo), s_hi) if s_lo <= s_hi else float(np.sqrt(s_lo * s_hi))
    width = np.log(hi / lo)
    # gap[i, j]: how far the ratio m_i / m_j is below its largest value max_i / min_j (log)
    gap = np.log(m[None, :] / lo[None, :]) - np.log(m[:, None] / hi[:, None])
    near = gap < share * (width[:, None] + width[None, :])
    np.fill_diagonal(near, False)
    words = {}
    for k, i in enumerate(idx):
        at_max, at_min = bool(near[k].any()), bool(near[:, k].any())
        bound = None
        if at_max != at_min:
            bound = "max" if at_max else "min"
        elif at_max:  # both: the nearer, in its own range
            bound = (
                "max" if np.log(hi[k] * scale / m[k]) < np.log(m[k] / (lo[k] * scale)) else "min"
            )
        words[i] = ParameterRow(
            key=genes[i].name,
            name=f"particle {genes[i].particle} mass (share of total_mass)",
            value=float(m[k]),
            lower=float(min(lo[k] * scale, m[k])),
            upper=float(max(hi[k] * scale, m[k])),
            log=True,
            bound=bound,
            unit="kg",
        )
    return words


def flagged(rows: Sequence[ParameterRow]) -> list[ParameterRow]:
    """The rows at or near a bound."""
    return [r for r in rows if r.bound is not None]


LISTED = 8  # parameters named in the line, at most


def bounds_line(rows: Sequence[ParameterRow]) -> str | None:
    """One line naming the parameters at or near a bound (``fit``'s summary), None if none:
    ``2 of 9 parameters at or near a search bound (within 1 % of the range): spring A-B
    stiffness = 1000 (near max 1000), ...``."""
    hits = flagged(rows)
    if not hits:
        return None
    listed = ", ".join(f"{r.name} = {r.value:.6g} ({r.bound_text()})" for r in hits[:LISTED])
    if len(hits) > LISTED:  # the rest: in the best model file
        listed += f", and {len(hits) - LISTED} more (the best model file holds every value)"
    return (
        f"{len(hits)} of {len(rows)} parameters at or near a search bound (within "
        f"{NEAR_BOUND * 100:g} % of the range; widen it and fit again): {listed}"
    )
