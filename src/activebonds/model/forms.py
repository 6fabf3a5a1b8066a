"""The four forms of a bond parameter (:class:`activebonds.bonds.Parameter`), one class each.

A form knows the shape of the parameter's array in ``params.bonds[kind]`` (N bonds of the
kind, D dimensions), the type of its file value in the schema (``schema``; ``expected`` in
words; ``check``: its size in the model), the numbers one bond puts in that array
(``entries``, the genes among them when the parameter is free; ``genes``: every gene it can
name), and how a fitted row is written back into the bond's file value (``write``):

* :class:`ScalarForm`: a number or ``{ value, min, max }``; [N]; one gene ``key``;
* :class:`VectorForm`: one value per axis (``anchor``); [N, D]; genes ``key[axis]``;
* :class:`WeightsForm`: the ``part`` list of a ``{ length, rate, min, max }`` table, a row
  over the bonds of the kind, the bond's own entry unused; [N, N]; genes ``key.part[j]``;
* :class:`ConstantForm`: a fixed vector of D numbers (a contact's ``normal``), never a gene;
  stored normalised, written back as the file gave it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import bonds
from .values import FiniteFloat, Param, Scalar, Vector, VectorParam, Weights

PARAMETER_EXPECTED = "expected a number or a table { value = .., min = .., max = .., fixed = .. }"
CONSTANT_ZERO = 1e-12  # a constant vector (a contact's normal) this short is refused as zero


def set_value(p, v):
    """A scalar file value ``p`` (number or :class:`Param`) set to ``v``, within its bounds."""
    if isinstance(p, Param):
        v = min(max(v, p.min if p.min is not None else v), p.max if p.max is not None else v)
        return p.model_copy(update={"value": float(v)})
    if p is None:
        return None
    return float(v)


@dataclass(frozen=True)
class Entry:
    """One number a bond puts in its parameter's array: where, its file value, the file's
    bounds and log choice for it (None: the parameter's defaults), and what tells it apart
    from the parameter's other numbers (a gene's ``axis``, or ``part`` and ``source``)."""

    where: int | tuple[int, int]
    value: Any  # a float; the unit vector of a constant
    lower: float | None = None
    upper: float | None = None
    log: bool | None = None
    axis: int | None = None
    part: str | None = None
    source: int | None = None


class ScalarForm:
    schema = Scalar
    expected = PARAMETER_EXPECTED

    def number(self, value) -> float | None:
        """The file's number, the one a parameter's :class:`~activebonds.bonds.Check` tests."""
        return value.value if isinstance(value, Param) else value

    def check(self, par: bonds.Parameter, value, where: str, d: int, n: int, kind: str) -> None:
        """Refuse a file value of the wrong size (``where``: ``bond[i].key`` in messages)."""

    def shape(self, n: int, d: int) -> tuple[int, ...]:
        return (n,)

    def entries(self, par: bonds.Parameter, p, pos: int, n: int, d: int) -> list[Entry]:
        free = isinstance(p, Param)
        value = p.value if free else float(p)
        log = p.log if free and par.log is None else par.log
        return [Entry(pos, value, p.min if free else None, p.max if free else None, log)]

    def genes(self, par: bonds.Parameter, n: int, d: int) -> list[dict]:
        return [{}]

    def write(self, par: bonds.Parameter, current, row, pos: int):
        return set_value(current, row)


class VectorForm:
    schema = Vector
    expected = "expected a list of numbers or a table { value = [..], min = .., max = .. }"

    def number(self, value) -> float | None:
        return None

    def check(self, par: bonds.Parameter, value, where: str, d: int, n: int, kind: str) -> None:
        vals = value if isinstance(value, list) else value.value
        if len(vals) != d:
            raise ValueError(f"{where}: expected {d} components, got {len(vals)}")
        if isinstance(value, VectorParam):
            for bound in (value.min, value.max):
                if isinstance(bound, list) and len(bound) != d:
                    raise ValueError(f"{where}: bounds need {d} components")

    def shape(self, n: int, d: int) -> tuple[int, ...]:
        return (n, d)

    def entries(self, par: bonds.Parameter, p, pos: int, n: int, d: int) -> list[Entry]:
        xs = p if isinstance(p, list) else p.value
        out = []
        for ax in range(d):
            lo = hi = None
            if isinstance(p, VectorParam):
                lo = p.min[ax] if isinstance(p.min, list) else p.min
                hi = p.max[ax] if isinstance(p.max, list) else p.max
            out.append(Entry((pos, ax), xs[ax], lo, hi, par.log, axis=ax))
        return out

    def genes(self, par: bonds.Parameter, n: int, d: int) -> list[dict]:
        return [{"axis": ax} for ax in range(d)]

    def write(self, par: bonds.Parameter, current, row, pos: int):
        xs = [float(x) for x in row]
        if not isinstance(current, VectorParam):
            return xs
        n = len(xs)  # within the bounds, as set_value keeps a scalar (rounding may cross one)
        lo = current.min if isinstance(current.min, list) else [current.min] * n
        hi = current.max if isinstance(current.max, list) else [current.max] * n
        xs = [
            min(max(x, a if a is not None else x), b if b is not None else x)
            for x, a, b in zip(xs, lo, hi, strict=True)
        ]
        return current.model_copy(update={"value": xs})


class WeightsForm:
    schema = Weights
    expected = "expected a table { length = .., rate = .., min = .., max = .. }"

    def number(self, value) -> float | None:
        return None

    def check(self, par: bonds.Parameter, value, where: str, d: int, n: int, kind: str) -> None:
        xs = getattr(value, par.part)
        if isinstance(xs, list) and len(xs) != n:
            raise ValueError(
                f"{where}.{par.part}: expected {n} entries (one per {kind} bond), got {len(xs)}"
            )

    def shape(self, n: int, d: int) -> tuple[int, ...]:
        return (n, n)

    def entries(self, par: bonds.Parameter, p, pos: int, n: int, d: int) -> list[Entry]:
        xs = getattr(p, par.part)
        xs = xs if isinstance(xs, list) else [xs] * n
        return [
            Entry((pos, j), xs[j], p.min, p.max, par.log, part=par.part, source=j)
            for j in range(n)
            if j != pos
        ]

    def genes(self, par: bonds.Parameter, n: int, d: int) -> list[dict]:
        return [{"part": par.part, "source": j} for j in range(n)]

    def write(self, par: bonds.Parameter, current, row, pos: int):
        xs = [0.0 if j == pos else float(x) for j, x in enumerate(row)]
        return current.model_copy(
            update={par.part: [min(max(x, current.min), current.max) for x in xs]}
        )


class ConstantForm:
    schema = list[FiniteFloat]
    expected = "expected a list of numbers (a fixed vector, never searched)"

    def number(self, value) -> float | None:
        return None

    def check(self, par: bonds.Parameter, value, where: str, d: int, n: int, kind: str) -> None:
        if len(value) != d:
            raise ValueError(f"{where}: expected {d} components, got {len(value)}")
        if math.sqrt(sum(x * x for x in value)) <= CONSTANT_ZERO:
            raise ValueError(f"{where}: must be a non-zero vector, got {value}")

    def shape(self, n: int, d: int) -> tuple[int, ...]:
        return (n, d)

    def entries(self, par: bonds.Parameter, p, pos: int, n: int, d: int) -> list[Entry]:
        vec = np.asarray(p, np.float64)
        return [Entry(pos, vec / np.linalg.norm(vec))]

    def genes(self, par: bonds.Parameter, n: int, d: int) -> list[dict]:
        return []

    def write(self, par: bonds.Parameter, current, row, pos: int):
        return current  # never a gene: written back as the file gave it


FORMS = {
    "scalar": ScalarForm(),
    "vector": VectorForm(),
    "weights": WeightsForm(),
    "constant": ConstantForm(),
}


def form_of(par: bonds.Parameter) -> ScalarForm | VectorForm | WeightsForm | ConstantForm:
    return FORMS[par.form]
