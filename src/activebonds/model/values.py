"""The file values of parameters: a number or ``{ value, min, max }`` table (:class:`Param`),
a vector (:class:`VectorParam`), a neural bond's input ``weights`` (:class:`Weights`).

The types each parameter form accepts (:mod:`activebonds.model.forms`); the model file's
schema (:mod:`activebonds.model.schema`) is made of them.
"""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import AfterValidator, BaseModel, ConfigDict, field_validator, model_validator


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
