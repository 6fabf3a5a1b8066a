"""Errors raised for bad input: one line that names the file, the field or line, and what is expected.

The command line turns an :class:`InputError` into that one line on stderr and exit code 2.
"""

from __future__ import annotations

from pathlib import Path


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
