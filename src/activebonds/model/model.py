"""A validated model: its spec, topology, genome layout, and the way back to a model file."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .layout import Gene, Layout, default_bounds, pick_log
from .params import Params, Topology
from .schema import Bond, ModelSpec, Param, VectorParam, Weights

# bond kind -> {file parameter: Params field}
_FIELDS = {
    "unary": {"stiffness": "unary_k", "damping": "unary_c"},
    "binary": {
        "stiffness": "k",
        "rest_length": "l0",
        "damping": "c",
        "gain": "gain",
        "threshold": "threshold",
    },
    "ternary": {"stiffness": "tern_k", "rest_angle": "tern_angle"},
}
_DEFAULTS = {"stiffness": 0.0, "damping": 0.0, "gain": 1.0, "threshold": 0.0}


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
    def params(self) -> Params:
        """The model file's values."""
        return self.layout.base

    def initial_state(self) -> tuple[np.ndarray, np.ndarray]:
        d = self.dimension
        x = np.array([p.position or [0.0] * d for p in self.spec.particle], dtype=np.float64)
        v = np.array([p.velocity or [0.0] * d for p in self.spec.particle], dtype=np.float64)
        return x, v

    def with_genome(self, genome: np.ndarray) -> Model:
        """The model with its free parameters set from a genome (search space)."""
        return build(with_values(self, self.layout.natural(genome)))


def build(spec: ModelSpec) -> Model:
    """Compile a validated spec into topology and genome layout."""
    names = {p.name: i for i, p in enumerate(spec.particle)}
    d = spec.dimension
    bonds = spec.bond
    unary = [b for b in bonds if b.kind == "unary"]
    binary = [b for b in bonds if b.kind == "binary"]
    ternary = [b for b in bonds if b.kind == "ternary"]
    n_b = len(binary)
    topology = Topology(
        n_particles=len(spec.particle),
        dimension=d,
        unary=np.array([names[b.particles[0]] for b in unary], dtype=np.int32).reshape(-1),
        binary=np.array([[names[n] for n in b.particles] for b in binary], dtype=np.int32).reshape(
            -1, 2
        ),
        neural=np.array([b.neural for b in binary], dtype=bool).reshape(-1),
        ternary=np.array(
            [[names[n] for n in b.particles] for b in ternary], dtype=np.int32
        ).reshape(-1, 3),
    )
    shapes = {
        "mass": (len(spec.particle),),
        "gravity": (d,),
        "unary_k": (len(unary),),
        "unary_c": (len(unary),),
        "unary_anchor": (len(unary), d),
        "k": (n_b,),
        "l0": (n_b,),
        "c": (n_b,),
        "gain": (n_b,),
        "threshold": (n_b,),
        "w_len": (n_b, n_b),
        "w_rate": (n_b, n_b),
        "tern_k": (len(ternary),),
        "tern_angle": (len(ternary),),
    }
    base = {f: np.zeros(s, dtype=np.float64) for f, s in shapes.items()}
    index = {f: np.full(s, -1, dtype=np.int32) for f, s in shapes.items()}
    base["gain"][:] = _DEFAULTS["gain"]
    if spec.gravity is not None:
        base["gravity"][:] = spec.gravity

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

    def put(field, where, kind, p, g, key, value, lower=None, upper=None, log=None):
        base[field][where] = value
        if not _is_free(p):
            return
        if (g, key) not in gene_of:
            lo, hi = default_bounds(kind, value)
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
        index[field][where] = gene_of[(g, key)]

    for i, p in enumerate(spec.particle):
        m = p.mass
        base["mass"][i] = _value(m)
        if _is_free(m):
            g = group(f"mass:{p.name}")
            slots[g].append(i)
            put("mass", i, "mass", m, g, "mass", m.value, m.min, m.max, m.log)

    counters = {"unary": 0, "binary": 0, "ternary": 0}
    for bi, b in enumerate(bonds):
        pos = counters[b.kind]
        counters[b.kind] += 1
        g = group(f"type:{b.type}" if b.type else f"bond[{bi}]")
        slots[g].extend(names[n] for n in b.particles)
        for pname, field in _FIELDS[b.kind].items():
            p = getattr(b, pname)
            if (
                p is None
                and pname not in ("stiffness", "damping")
                and not (b.neural and pname in ("gain", "threshold"))
            ):
                continue
            v = _value(p, _DEFAULTS.get(pname, 0.0))
            lo = p.min if isinstance(p, Param) else None
            hi = p.max if isinstance(p, Param) else None
            lg = p.log if isinstance(p, Param) else None
            put(field, pos, pname, p, g, pname, v, lo, hi, lg)
        if b.kind == "unary" and b.anchor is not None:
            a = b.anchor
            vals = a if isinstance(a, list) else a.value
            for ax in range(d):
                lo = hi = None
                if isinstance(a, VectorParam):
                    lo = a.min[ax] if isinstance(a.min, list) else a.min
                    hi = a.max[ax] if isinstance(a.max, list) else a.max
                put("unary_anchor", (pos, ax), "anchor", a, g, f"anchor[{ax}]", vals[ax], lo, hi)
        if b.kind == "binary" and b.neural and b.weights is not None:
            w = b.weights
            for field, attr in (("w_len", "length"), ("w_rate", "rate")):
                xs = getattr(w, attr)
                xs = xs if isinstance(xs, list) else [xs] * n_b
                for j in range(n_b):
                    if j == pos:
                        continue
                    key = f"weights.{attr}[{j}]"
                    put(field, (pos, j), "threshold", w, g, key, xs[j], w.min, w.max, False)

    width = max([len(s) for s in slots.values()] + [1])
    group_slots = np.full((len(groups), width), -1, dtype=np.int32)
    for g, ps in slots.items():
        group_slots[g, : len(ps)] = ps
    layout = Layout(
        genes=tuple(genes),
        groups=tuple(groups),
        group_slots=group_slots,
        base=Params(**base),
        index=Params(**index),
    )
    return Model(spec=spec, topology=topology, layout=layout)


def with_values(model: Model, values: np.ndarray) -> ModelSpec:
    """A spec equal to the model's, with every free parameter set to ``values`` (natural units)."""
    layout = model.layout
    values = np.concatenate([np.asarray(values, dtype=np.float64).reshape(-1), [0.0]])
    params = Params(
        *(
            np.where(np.asarray(i) >= 0, np.asarray(values)[np.maximum(np.asarray(i), 0)], b)
            if np.asarray(i).size
            else b
            for b, i in zip(layout.base, layout.index, strict=True)
        )
    )
    return spec_with_params(model.spec, params)


def spec_with_params(spec: ModelSpec, params: Params) -> ModelSpec:
    """Write numbers back into a spec, keeping which parameters are free and their bounds."""

    def setp(p, v):
        if isinstance(p, Param):
            v = min(max(v, p.min if p.min is not None else v), p.max if p.max is not None else v)
            return p.model_copy(update={"value": float(v)})
        if p is None:
            return None
        return float(v)

    particles = [
        p.model_copy(update={"mass": setp(p.mass, params.mass[i])})
        for i, p in enumerate(spec.particle)
    ]
    counters = {"unary": 0, "binary": 0, "ternary": 0}
    bonds: list[Bond] = []
    for b in spec.bond:
        pos = counters[b.kind]
        counters[b.kind] += 1
        update: dict[str, Any] = {}
        for pname, field in _FIELDS[b.kind].items():
            p = getattr(b, pname)
            if p is not None:
                update[pname] = setp(p, getattr(params, field)[pos])
        if b.kind == "unary" and b.anchor is not None:
            vals = [float(x) for x in params.unary_anchor[pos]]
            a = b.anchor
            update["anchor"] = (
                a.model_copy(update={"value": vals}) if isinstance(a, VectorParam) else vals
            )
        if b.kind == "binary" and b.neural and b.weights is not None:
            row_l = [0.0 if j == pos else float(x) for j, x in enumerate(params.w_len[pos])]
            row_r = [0.0 if j == pos else float(x) for j, x in enumerate(params.w_rate[pos])]
            lo, hi = b.weights.min, b.weights.max
            row_l = [min(max(x, lo), hi) for x in row_l]
            row_r = [min(max(x, lo), hi) for x in row_r]
            update["weights"] = b.weights.model_copy(update={"length": row_l, "rate": row_r})
        bonds.append(b.model_copy(update=update))
    return spec.model_copy(update={"particle": particles, "bond": bonds})
