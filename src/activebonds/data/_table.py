"""The text-table readers' shared part (CSV and TRC: :mod:`.read_csv`, :mod:`.read_trc`):
lines, data rows parsed to numbers, an incomplete last row (an interrupted export) found and
dropped, the time column checked against the declared rates, and the trajectory of the rows.

Everything here raises :class:`activebonds.errors.InputError` naming the file at fault.
"""

from __future__ import annotations

import math
import re
import warnings
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from activebonds.data._common import (
    RATE_TOLERANCE,
    TruncatedRowWarning,
    file_trajectory,
    read_text,
    reconcile_rates,
    to_metres,
)
from activebonds.data.trajectory import Trajectory
from activebonds.errors import InputError


def parse_float(text: str, source: str | Path, where: str, what: str) -> float:
    """Parse one number from a text file; blank, "nan" and "NaN" give NaN (missing).

    Anything else that is not a finite decimal number raises InputError naming ``where``
    (line and column) and ``what`` (column name).
    """
    s = text.strip()
    if not s:
        return math.nan
    try:
        if "_" in s:  # float() accepts "1_000"; a data file should not
            raise ValueError(s)
        value = float(s)
    except ValueError:
        raise InputError(
            source, f"column {what}: {_short(s)!r} is not a number", where=where
        ) from None
    if math.isinf(value):
        raise InputError(
            source, f"column {what}: {_short(s)!r} is not a finite number", where=where
        )
    return value


def _short(s: str, n: int = 40) -> str:
    return s if len(s) <= n else s[:n] + "..."


def decimals_of(text: str) -> int:
    """Number of decimal places written in a number ("0.017" -> 3, "1e-3" -> 3, "2" -> 0)."""
    try:
        exponent = Decimal(text.strip()).as_tuple().exponent
    except (InvalidOperation, ValueError):
        return 0
    return max(0, -exponent) if isinstance(exponent, int) else 0


def rate_from_times(times: np.ndarray, resolution: float, source: str | Path) -> float:
    """Robust sample-rate estimate from a time column.

    ``(n - 1) / (t_last - t_first)`` is only known to within the rounding of the column
    (``resolution``, e.g. 1e-3 for a column written with 3 decimals).  The estimate is
    snapped to the number with the fewest decimals inside that uncertainty, so a 60 Hz
    column rounded to milliseconds gives exactly 60.0 rather than 599 / 9.983.
    """
    n = len(times)
    span = float(times[-1] - times[0])
    if n < 2 or not span > 0:
        raise InputError(source, "time column does not increase; cannot derive the sample rate")
    raw = (n - 1) / span
    eps = 4 * np.finfo(float).eps * max(abs(float(times[0])), abs(float(times[-1])), 1.0)
    tolerance = raw * (max(resolution, eps) / span) + 1e-12 * raw
    for digits in range(0, 16):
        candidate = round(raw, digits)
        if candidate > 0 and abs(candidate - raw) <= tolerance:
            return float(candidate)
    return float(raw)


def check_time_column(
    times: np.ndarray,
    resolution: float,
    source: str | Path,
    declared: list[tuple[str, float]],
    lines: list[int] | None = None,
) -> tuple[float, float]:
    """Check a time column against declared rates; return (rate estimate, start time).

    ``declared`` lists (description, rate) pairs such as ("sample rate", 50.0); each must
    agree with the column within :data:`RATE_TOLERANCE`.  The column must also be uniformly
    sampled (no missing or duplicated rows): every time within a quarter of a sample
    interval (plus the rounding) of the straight line through the first and last times.
    """
    estimate = rate_from_times(times, resolution, source)
    for label, rate in declared:
        if abs(rate - estimate) > RATE_TOLERANCE * estimate:
            raise InputError(
                source,
                f"{label} {rate:g} Hz disagrees with the time column ({estimate:g} Hz)",
            )
    expected = times[0] + np.arange(len(times)) * ((times[-1] - times[0]) / (len(times) - 1))
    deviation = np.abs(times - expected)
    worst = int(np.argmax(deviation))
    if deviation[worst] > 0.25 / estimate + resolution:
        where = f"line {lines[worst]}" if lines is not None else f"frame {worst + 1}"
        raise InputError(
            source,
            f"time column is not uniformly sampled at {estimate:g} Hz (time {times[worst]:g} s, "
            f"expected about {expected[worst]:g} s); missing or duplicated rows?",
            where=where,
        )
    return estimate, float(times[0])


def data_lines(text: str) -> list[str]:
    """Split text into lines on LF, dropping a trailing CR (CRLF files) but nothing else."""
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return [line[:-1] if line.endswith("\r") else line for line in lines]


def ends_with_line_break(text: str) -> bool:
    """True if the text after the last non-blank character contains a line break."""
    return "\n" in text[len(text.rstrip()) :]


def read_lines(path: Path) -> tuple[list[str], bool]:
    """A text file's lines (:func:`data_lines` of :func:`read_text`) and whether it ends with
    a line break (:func:`ends_with_line_break`: else its last row may be cut short)."""
    text = read_text(path)
    return data_lines(text), ends_with_line_break(text)


#: A field that may be the beginning of a number cut short ("12.", "1e", "-", "na").
_NUMBER_PREFIX = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d*)?(?:[eE][+-]?\d*)?|[+-]?[nN][aA]?")
#: How a number is written: digits after the point and exponent digits (None: absent).
_NUMBER_SHAPE = re.compile(r"[+-]?\d*(?:\.(\d*))?(?:[eE][+-]?(\d*))?")
#: Values of the same column, besides the last row's, needed to trust a fixed format,
#: and how many rows before the last are looked at.
_SHAPE_EVIDENCE = 3
_SHAPE_ROWS = 1000


def _shape(text: str) -> tuple[int | None, int | None] | None:
    match = _NUMBER_SHAPE.fullmatch(text.strip())
    if match is None or not any(c.isdigit() for c in text):
        return None
    point, exponent = match.group(1), match.group(2)
    return (
        None if point is None else len(point),
        None if exponent is None else len(exponent),
    )


def _shorter(got: tuple[int | None, int | None], written: tuple[int | None, int | None]) -> bool:
    """Whether a number shaped ``got`` can be a cut copy of one shaped ``written``."""
    (decimals, exponent), (full_decimals, full_exponent) = got, written
    if full_exponent is None:  # 617.24762 -> 617.2 or 617
        return exponent is None and full_decimals is not None and (decimals or 0) < full_decimals
    if exponent is None:  # 6.1724762e+02 -> 6.17
        return True
    return decimals == full_decimals and exponent < full_exponent  # -> 6.1724762e+0


def _cut_number(rows: list[tuple[int, list[str]]], column: int) -> str | None:
    """Why the last field of the last row looks like a number cut short, or None.

    Only called for a file without a final line break.  The field is cut if it is the
    beginning of a number but not a number ("12.3e", "-"), or if it is written with
    fewer digits than the other values of its column when that column has a fixed format
    (at least three values in the 1,000 rows before, all with the same number of decimals
    and exponent digits): "617.2" where the column is written "617.24762".
    """
    text = rows[-1][1][column].strip()
    try:
        float(text)
    except ValueError:
        if _NUMBER_PREFIX.fullmatch(text):
            return f"ends in {text!r}, only the beginning of a number"
        return None  # not a number at all: parse_rows reports it
    shape = _shape(text)
    if shape is None:
        return None  # "nan"
    shapes = set()
    example = ""
    count = 0
    for _, fields in reversed(rows[-1 - _SHAPE_ROWS : -1]):
        if len(fields) > column and fields[column].strip():
            other = _shape(fields[column])
            if other is None:
                continue
            shapes.add(other)
            example = example or fields[column].strip()
            count += 1
            if len(shapes) > 1:
                return None
    if count < _SHAPE_EVIDENCE or not _shorter(shape, next(iter(shapes))):
        return None
    return f"ends in {text!r} where the rows before write its column like {example!r}"


def incomplete_last_row(
    rows: list[tuple[int, list[str]]], n_fields: int, final_newline: bool
) -> str | None:
    """What is incomplete about the last data row (an interrupted export), or None.

    ``rows`` holds (line number, fields) of the non-blank data rows; ``n_fields`` is the
    number of header columns.  The last row is incomplete when

    * it has fewer fields than the header (the file was cut inside the row), or
    * the file does not end with a line break (the writer never finished the row) and the
      row's last field is empty, is only the beginning of a number ("1e-", "-", "."),
      or has fewer digits than the other values of a fixed-format column (the column is
      written "617.24762" in the rows before, and here "617.2").

    A full-width last row without a final line break is otherwise complete: many writers
    omit the last line break, and a number cut in a column of varying format cannot be
    told from a short one.
    """
    if not rows:
        return None
    fields = rows[-1][1]
    if len(fields) < n_fields:
        what = f"has only {len(fields)} of the header's {n_fields} fields"
    elif final_newline or len(fields) > n_fields:
        return None
    elif not fields[n_fields - 1].strip():
        what = "ends in an empty field"
    else:
        what = _cut_number(rows, n_fields - 1)
        if what is None:
            return None
    return what if final_newline else f"{what}, with no line break at the end of the file"


def drop_incomplete_row(
    source: str | Path,
    rows: list[tuple[int, list[str]]],
    what: str | None,
    strict: bool = False,
) -> list[tuple[int, list[str]]]:
    """The rows without the last one if :func:`incomplete_last_row` found it incomplete.

    ``what`` is that function's finding (None: nothing to drop).  With ``strict`` an
    incomplete row is an :class:`InputError` naming its line, and so is an incomplete row
    that is the only data row.  The reader calls :func:`warn_incomplete_row` once the
    rest of the file has been read.  (A short row anywhere else is reported by
    :func:`parse_rows`.)
    """
    if what is None:
        return rows
    if strict or len(rows) == 1:
        row = "the only data row" if len(rows) == 1 else "last row"
        raise InputError(
            source, f"{row} {what}: truncated or incomplete row", where=f"line {rows[-1][0]}"
        )
    return rows[:-1]


def warn_incomplete_row(source: str | Path, line: int, what: str, kept: int) -> None:
    """The one :class:`TruncatedRowWarning` of a file whose incomplete last row was dropped."""
    warnings.warn(
        TruncatedRowWarning(
            source,
            line,
            f"last row {what}: truncated file (an interrupted export?); dropped that row "
            f"and read the {kept} row{'s' if kept != 1 else ''} before it",
        ),
        stacklevel=5,  # the reader's caller: read_trajectory's
    )


def parse_rows(
    source: str | Path,
    rows: list[tuple[int, list[str]]],
    columns: list[str],
    coord_cols: list[int],
    time_col: int | None,
    frame_col: int | None,
    final_newline: bool = True,
) -> tuple[np.ndarray, list[str]]:
    """Parse the data rows of a text table.

    ``rows`` holds (line number, fields); ``columns`` the header names (their count is the
    number of fields a row must have; extra fields must be blank).  Returns the coordinate
    values [rows, len(coord_cols)] (NaN for blank/"nan") and the raw time strings.
    A short row is reported with its line number (a truncated file), never dropped; so is
    a last row whose last field is empty when the file does not end with a line break
    (``final_newline`` False), the signature of a file cut just after a separator.
    """
    n_fields = len(columns)
    values = np.empty((len(rows), len(coord_cols)), dtype=np.float64)
    time_strings: list[str] = []
    for r, (line_no, fields) in enumerate(rows):
        where = f"line {line_no}"
        if len(fields) < n_fields:
            raise InputError(
                source,
                f"row has {len(fields)} fields but the header has {n_fields} "
                "(truncated or incomplete row)",
                where=where,
            )
        if len(fields) > n_fields and any(f.strip() for f in fields[n_fields:]):
            raise InputError(
                source, f"row has {len(fields)} fields but the header has only {n_fields}", where
            )
        if not final_newline and r == len(rows) - 1 and not fields[n_fields - 1].strip():
            raise InputError(
                source, "last row ends in an empty field and no line break (truncated file?)", where
            )
        for k in (frame_col, time_col):
            if k is not None:
                number = parse_float(fields[k], source, where, repr(columns[k]))
                if math.isnan(number):
                    raise InputError(source, f"column {columns[k]!r} is empty or NaN", where=where)
        if time_col is not None:
            time_strings.append(fields[time_col])
        row = values[r]
        for j, c in enumerate(coord_cols):
            text = fields[c]
            try:
                if "_" in text:
                    raise ValueError(text)
                row[j] = float(text)
            except ValueError:
                row[j] = parse_float(text, source, where, repr(columns[c]))
        if np.isinf(row).any():
            j = int(np.flatnonzero(np.isinf(row))[0])
            parse_float(fields[coord_cols[j]], source, where, repr(columns[coord_cols[j]]))
    return values, time_strings


def times_from_strings(source: str | Path, strings: list[str]) -> tuple[np.ndarray, float]:
    """Time column values and their rounding resolution (10**-decimals written)."""
    times = np.array([float(s) for s in strings], dtype=np.float64)
    resolution = 10.0 ** -max((decimals_of(s) for s in strings), default=0)
    return times, resolution


def masked_positions(values: np.ndarray, n_markers: int, dim: int, units: str) -> tuple:
    """Reshape [frames, markers*dim] values to positions in metres and the presence mask.

    A marker-frame is present only if all its coordinates are numbers; a partly blank
    sample is missing as a whole.
    """
    positions = values.reshape(values.shape[0], n_markers, dim)
    mask = np.all(np.isfinite(positions), axis=-1)
    positions = to_metres(positions, units)
    positions[~mask] = np.nan
    return positions, mask


def resolve_rate(
    source: str | Path,
    declared: list[tuple[str, float]],
    time_strings: list[str],
    lines: list[int],
) -> tuple[float, float]:
    """Sample rate and start time from declared rates and an optional time column.

    The first declared rate wins (all declared rates must agree within 1 %); with a time
    column of two or more rows, every declared rate must agree with it, and with no
    declared rate the rate is estimated from it.  The start time is the first time value.
    """
    rate = reconcile_rates(source, declared)
    if not time_strings:
        if rate is None:
            raise InputError(
                source,
                "no time column and no sample rate given; add a time column or a line '# rate: <Hz>' before the header (or pass rate= to read_trajectory)",
            )
        return rate, 0.0
    times, resolution = times_from_strings(source, time_strings)
    if len(times) < 2:
        if rate is None:
            raise InputError(
                source,
                "a single frame gives no sample rate; add a line '# rate: <Hz>' before the header (or pass rate= to read_trajectory)",
            )
        return rate, float(times[0])
    estimate, start = check_time_column(times, resolution, source, declared, lines)
    return (rate if rate is not None else estimate), start


def table_trajectory(
    source: Path,
    rows: list[tuple[int, list[str]]],
    parsed: tuple[np.ndarray, list[str]],
    declared: list[tuple[str, float]],
    markers: list[str] | tuple[str, ...],
    dim: int,
    units: str,
    dropped: tuple[str | None, int],
) -> Trajectory:
    """The trajectory of a text table's data ``rows``, ``parsed`` by :func:`parse_rows`: its
    rate and start time from the ``declared`` rates and the time column
    (:func:`resolve_rate`), its positions in metres (:func:`masked_positions`); then the
    warning of an incomplete last row dropped (``dropped``: what
    :func:`incomplete_last_row` found, or None, and that row's line)."""
    values, time_strings = parsed
    rate, start_time = resolve_rate(source, declared, time_strings, [n for n, _ in rows])
    positions, mask = masked_positions(values, len(markers), dim, units)
    trajectory = file_trajectory(source, positions, mask, markers, rate, start_time, units)
    what, line = dropped
    if what is not None:
        warn_incomplete_row(source, line, what, len(rows))
    return trajectory
