"""What a notebook shows of an object: a small HTML table, every text escaped.

The ``_repr_html_`` of :class:`~activebonds.data.Trajectory`, :class:`~activebonds.model.Model`,
:class:`~activebonds.identify.driver.FitResult` and the run records go through
:func:`html_table`; their ``__repr__`` stays one line. Numbers are shown with four significant
digits; long lists are cut to their first names.
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Sequence

STYLE = "border-collapse:collapse;text-align:left"
CELL = "padding:1px 8px;text-align:left;vertical-align:top"


def number(x: object, unit: str = "") -> str:
    """``x`` with four significant digits (``—`` for None or NaN), then ``unit``."""
    if x is None:
        return "—"
    try:
        value = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return str(x)
    if math.isnan(value):
        return "—"
    text = "∞" if math.isinf(value) else f"{value:.4g}"
    return f"{text} {unit}".rstrip()


def names(items: Iterable[str], limit: int = 8) -> str:
    """The first ``limit`` names, comma-separated, ``…`` and the count of the rest after."""
    items = list(items)
    shown = ", ".join(items[:limit])
    return shown + (f", … ({len(items) - limit} more)" if len(items) > limit else "")


def html_table(title: str, rows: Sequence[tuple[str, object]]) -> str:
    """An HTML table captioned ``title`` with one (name, value) row each; values as text."""
    body = "".join(
        f'<tr><th style="{CELL}">{html.escape(str(k))}</th>'
        f'<td style="{CELL}">{html.escape(str(v))}</td></tr>'
        for k, v in rows
    )
    caption = f'<caption style="text-align:left"><b>{html.escape(title)}</b></caption>'
    return f'<table style="{STYLE}">{caption}{body}</table>'
