"""A report as data: titled sections of text, tables and figures.

Post-fit stages (:mod:`activebonds.identify.stages`) say what the report shows of their
records with these; :mod:`activebonds.report.html` renders them. Plain frozen dataclasses, no
rendering here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path


@dataclass(frozen=True)
class Figure:
    """A PNG figure to embed (its SVG twin, if any, stays beside it on disk)."""

    path: Path
    caption: str = ""


@dataclass(frozen=True)
class Marked:
    """A table cell shown with a warning (e.g. a model's error where it does not beat zero
    force: red in the report); ``value`` is rendered as any other cell's."""

    value: object
    why: str = ""  # a tooltip, in words


@dataclass(frozen=True)
class Table:
    columns: Sequence[str]
    rows: Sequence[Sequence[object]]
    caption: str = ""
    key_value: bool = False  # two columns: a header cell then a value


@dataclass(frozen=True)
class Section:
    """A titled part of a report: text paragraphs, tables, figures, and optionally a player
    for an :func:`activebonds.report.animation.payload`."""

    title: str
    text: Sequence[str] = ()
    tables: Sequence[Table] = ()
    figures: Sequence[Figure | Path] = ()
    animation: dict | None = None
    anchor: str = ""
    notes: Sequence[str] = field(default_factory=tuple)
