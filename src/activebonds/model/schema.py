"""The model file's schema (DESIGN.md §4), validated with pydantic.

A model file is TOML: top-level ``name``, ``dimension``, optional ``gravity``; ``[[particle]]``
tables and ``[[bond]]`` tables. Every parameter is a number (fixed) or a table
``{ value = .., min = .., max = .., fixed = false, log = .. }``. Vector parameters (``anchor``,
``gravity``) take lists; neural ``weights`` take ``length`` and ``rate`` lists with one entry per
binary bond of the model (in file order; a neuron's own entry is ignored and written as 0).
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator, model_validator


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


def _finite(x: float, what: str = "value") -> float:
    if not math.isfinite(x):
        raise ValueError(f"{what} must be a finite number, got {x}")
    return x


FiniteFloat = Annotated[float, AfterValidator(_finite)]


def _value_of(p: float | Param | None) -> float | None:
    return p.value if isinstance(p, Param) else p


class Param(_Strict):
    """A scalar parameter: fixed, or free within [min, max] (log-scaled search if ``log``)."""

    value: float
    min: float | None = None
    max: float | None = None
    fixed: bool = False
    log: bool | None = None

    @field_validator("value", "min", "max")
    @classmethod
    def _check_finite(cls, x: float | None) -> float | None:
        return None if x is None else _finite(x)

    @model_validator(mode="after")
    def _check_bounds(self) -> Param:
        if self.min is not None and self.max is not None and self.min >= self.max:
            raise ValueError(f"min: min ({self.min}) must be below max ({self.max})")
        if self.min is not None and self.value < self.min:
            raise ValueError(f"value {self.value} is below min {self.min}")
        if self.max is not None and self.value > self.max:
            raise ValueError(f"value {self.value} is above max {self.max}")
        if self.log and self.min is not None and self.min <= 0:
            raise ValueError("a log-scaled parameter needs min > 0")
        return self


class VectorParam(_Strict):
    """A vector parameter (anchor, gravity): one value per axis, shared scalar or per-axis bounds."""

    value: list[FiniteFloat]
    min: FiniteFloat | list[FiniteFloat] | None = None
    max: FiniteFloat | list[FiniteFloat] | None = None
    fixed: bool = False

    @model_validator(mode="after")
    def _check_bounds(self) -> VectorParam:
        n = len(self.value)
        for name in ("min", "max"):
            b = getattr(self, name)
            if isinstance(b, list) and len(b) != n:
                raise ValueError(f"{name}: expected {n} components, got {len(b)}")
        lo = self.min if isinstance(self.min, list) else [self.min] * n
        hi = self.max if isinstance(self.max, list) else [self.max] * n
        for ax, (v, a, b) in enumerate(zip(self.value, lo, hi, strict=True)):
            if a is not None and b is not None and a >= b:
                raise ValueError(f"min: min ({a}) must be below max ({b}) on axis {ax}")
            if a is not None and v < a:
                raise ValueError(f"value: component {ax} = {v} is below min {a}")
            if b is not None and v > b:
                raise ValueError(f"value: component {ax} = {v} is above max {b}")
        return self


class Weights(_Strict):
    """Neural input weights of one mechanical-neural bond (DESIGN.md §2).

    ``length[j]`` multiplies the elongation of binary bond j, ``rate[j]`` its elongation rate.
    A scalar is broadcast to every other binary bond.
    """

    length: FiniteFloat | list[FiniteFloat] = 0.0
    rate: FiniteFloat | list[FiniteFloat] = 0.0
    min: FiniteFloat = -10.0
    max: FiniteFloat = 10.0
    fixed: bool = False

    @model_validator(mode="after")
    def _check(self) -> Weights:
        if self.min >= self.max:
            raise ValueError(f"min: min ({self.min}) must be below max ({self.max})")
        for name in ("length", "rate"):
            xs = getattr(self, name)
            for x in xs if isinstance(xs, list) else [xs]:
                if not self.min <= x <= self.max:
                    raise ValueError(
                        f"{name}: weight {x} outside [min, max] = [{self.min}, {self.max}]"
                    )
        return self


Scalar = FiniteFloat | Param
Vector = list[FiniteFloat] | VectorParam


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


_KIND_PARAMS = {
    "unary": {"stiffness", "damping", "anchor"},
    "binary": {"stiffness", "rest_length", "damping", "gain", "weights", "threshold"},
    "ternary": {"stiffness", "rest_angle"},
}
_NEURAL_ONLY = {"gain", "weights", "threshold"}


class Bond(_Strict):
    kind: Literal["unary", "binary", "ternary"]
    particles: list[str]
    type: str | None = None
    neural: bool = False
    stiffness: Scalar | None = None
    rest_length: Scalar | None = None
    damping: Scalar | None = None
    anchor: Vector | None = None
    rest_angle: Scalar | None = None
    gain: Scalar | None = None
    weights: Weights | None = None
    threshold: Scalar | None = None

    @model_validator(mode="after")
    def _check_kind(self) -> Bond:
        arity = {"unary": 1, "binary": 2, "ternary": 3}[self.kind]
        # Messages start with the field at fault ("field: ..."); the loader adds it to the path.
        if len(self.particles) != arity:
            raise ValueError(
                f"particles: a {self.kind} bond needs {arity} particle name(s), "
                f"got {len(self.particles)}"
            )
        if len(set(self.particles)) != arity:
            raise ValueError(f"particles: a {self.kind} bond needs {arity} distinct particles")
        if self.neural and self.kind != "binary":
            raise ValueError("neural: only binary bonds can be neural")
        allowed = _KIND_PARAMS[self.kind]
        for name in _KIND_PARAMS["binary"] | _KIND_PARAMS["unary"] | _KIND_PARAMS["ternary"]:
            if getattr(self, name) is not None and name not in allowed:
                raise ValueError(f"{name}: not a parameter of a {self.kind} bond")
        for name in _NEURAL_ONLY:
            if getattr(self, name) is not None and not self.neural:
                raise ValueError(f"{name}: '{name}' needs neural = true")
        if self.kind == "binary" and self.rest_length is None:
            raise ValueError("rest_length: a binary bond needs rest_length")
        if self.kind == "ternary" and self.rest_angle is None:
            raise ValueError("rest_angle: a ternary bond needs rest_angle (radians)")
        for name in ("stiffness", "damping", "rest_length"):
            value = _value_of(getattr(self, name))
            if value is not None and value < 0:
                raise ValueError(f"{name}: must be >= 0, got {value}")
        value = _value_of(self.rest_angle)
        if value is not None and not 0.0 <= value <= math.pi:
            raise ValueError(f"rest_angle: must be in [0, pi] radians, got {value}")
        return self


class ModelSpec(_Strict):
    """The whole model file."""

    name: str = "model"
    dimension: Literal[2, 3] = 3
    gravity: list[float] | None = None
    particle: list[Particle] = Field(min_length=1)
    bond: list[Bond] = Field(default_factory=list)

    @model_validator(mode="after")
    def _check_references(self) -> ModelSpec:
        d = self.dimension
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
        if self.gravity is not None:
            if len(self.gravity) != d:
                raise ValueError(f"gravity: expected {d} components, got {len(self.gravity)}")
            for g in self.gravity:
                _finite(g, "gravity")
        for i, p in enumerate(self.particle):
            for field in ("position", "velocity"):
                vec = getattr(p, field)
                if vec is not None and len(vec) != d:
                    raise ValueError(
                        f"particle[{i}].{field}: expected {d} components, got {len(vec)}"
                    )
        n_binary = sum(b.kind == "binary" for b in self.bond)
        types: dict[str, tuple[str, bool]] = {}
        for i, b in enumerate(self.bond):
            for name in b.particles:
                if name not in seen:
                    raise ValueError(f"bond[{i}].particles: unknown particle '{name}'")
            if b.anchor is not None:
                vals = b.anchor if isinstance(b.anchor, list) else b.anchor.value
                if len(vals) != d:
                    raise ValueError(f"bond[{i}].anchor: expected {d} components, got {len(vals)}")
                if isinstance(b.anchor, VectorParam):
                    for bound in (b.anchor.min, b.anchor.max):
                        if isinstance(bound, list) and len(bound) != d:
                            raise ValueError(f"bond[{i}].anchor: bounds need {d} components")
            if b.weights is not None:
                for field in ("length", "rate"):
                    xs = getattr(b.weights, field)
                    if isinstance(xs, list) and len(xs) != n_binary:
                        raise ValueError(
                            f"bond[{i}].weights.{field}: expected {n_binary} entries "
                            f"(one per binary bond), got {len(xs)}"
                        )
            if b.type is not None:
                sig = (b.kind, b.neural)
                if b.type in types and types[b.type] != sig:
                    raise ValueError(
                        f"bond[{i}].type: bonds of type '{b.type}' must share kind and neural"
                    )
                types[b.type] = sig
        return self
