"""Errors raised for bad input: one line that names the file, the field or line, and what is expected.

The command line turns an :class:`InputError` into that one line on stderr and exit code 2.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple


class InputError(Exception):
    """Bad user input (model file, trajectory file, option, run directory).

    ``source`` is the file (or option) at fault, ``where`` the field path or line, ``message``
    says what is wrong and what is expected.
    """

    def __init__(self, source: str | Path | None, message: str, where: str | None = None):
        self.source = str(source) if source is not None else None
        self.where = where
        self.message = message
        super().__init__(self.line())

    def line(self) -> str:
        parts = [p for p in (self.source, self.where) if p]
        prefix = ": ".join(parts)
        text = f"{prefix}: {self.message}" if prefix else self.message
        return " ".join(text.split())  # always one line


class DivergenceError(ArithmeticError):
    """A simulation went non-finite; names the first bad step and the particle involved."""


class Problem(NamedTuple):
    """One problem of a pydantic ``ValidationError``: where (``loc``, the field path), its
    ``kind`` (pydantic's error type) and the ``message`` without pydantic's "Value error, "."""

    loc: tuple
    kind: str
    message: str

    @property
    def field(self) -> str:
        """The top-level field at fault ('' for the whole object)."""
        return str(self.loc[0]) if self.loc else ""

    @property
    def path(self) -> str:
        """The field path, dotted: ``fit.0.model``."""
        return ".".join(str(p) for p in self.loc)


def first_problem(error) -> Problem:
    """The problem of a pydantic ``ValidationError`` that its one line names: an unknown key
    (the likeliest typo) before any other, else the first."""
    errors = error.errors()
    first = min(errors, key=lambda e: e["type"] != "extra_forbidden")
    return Problem(tuple(first["loc"]), first["type"], first["msg"].removeprefix("Value error, "))


def option_error(error) -> InputError:
    """A pydantic ``ValidationError`` of settings built from options, as the one line of the
    option at fault: ``--max-steps: ...`` (``options: ...`` for a check of several)."""
    problem = first_problem(error)
    name = "--" + problem.field.replace("_", "-") if problem.field else "options"
    return InputError(name, problem.message)
