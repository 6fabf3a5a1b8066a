"""Reader for wide CSV marker files (the VHDC horse files and the generic layout we write).

Layout (comma separated, LF or CRLF, optional UTF-8 BOM, fields may be quoted)::

    # units: mm            <- optional leading comment lines "# key: value" (no commas)
    # rate: 60             <-   keys used: units, rate; other comments are ignored
    "Frame#","Time","HeadX","HeadY","HeadZ","WithersX",...
    1,0.000,955.40527,-88.41407,1372.53247,...

* An optional frame column first ("Frame#", "Frame", "Frame number", ...; must hold
  numbers, otherwise unused), then an optional time column in seconds ("Time", "t",
  "Time (s)", ...).
* Then one group per marker of 2 or 3 columns ``<Name>X, <Name>Y[, <Name>Z]``; the axis
  letter may follow a separator (``Head X``, ``Head_x``, ``Head.X``) and is case-blind.
  Every marker must have the same axes, in X, Y[, Z] order.
* Units: the ``units`` argument of :func:`read_trajectory` if given, else a leading
  ``# units: <mm|cm|m>`` comment, else **millimetres** (the motion-capture default), with a
  :class:`~activebonds.data._common.UnitsWarning` where the markers then span less than a
  centimetre (a body in metres read as millimetres).
* Rate: the ``rate`` argument if given, else a ``# rate: <Hz>`` comment, else estimated
  from the time column (snapped to its rounding, so a 60 Hz column written with 3 decimals
  gives exactly 60).  Declared rates that disagree with the time column by more than 1 %
  are an error; so is a time column that is not uniformly sampled.
* Blank fields and ``nan`` are missing samples; a row with fewer fields than the header
  or a non-number is an error naming the line and column.
* An incomplete **last** row (an interrupted export: fewer fields than the header, or no
  final line break after an empty field or a number cut short; see
  :func:`~activebonds.data._common.incomplete_last_row`) is dropped with a
  :class:`~activebonds.data._common.TruncatedRowWarning` naming the line; with
  ``strict=True`` it is an error naming the line.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

from activebonds.data._common import (
    declared_rates,
    positive_rate,
    units_of,
    warn_small_span,
)
from activebonds.data._table import (
    drop_incomplete_row,
    incomplete_last_row,
    parse_rows,
    read_lines,
    table_trajectory,
)
from activebonds.data.trajectory import Trajectory, check_marker_names
from activebonds.errors import InputError

_FRAME_NAMES = {"frame#", "frame", "frames", "frameno", "framenumber", "#"}
_TIME_NAMES = {"time", "t", "times", "ts", "timesec", "seconds", "sec"}
_AXIS = re.compile(r"(.*?)[\s_.:-]?([XYZxyz])")
_META = re.compile(r"#\s*([A-Za-z_]+)\s*[:=]\s*(.*?)\s*")

#: Characters that may separate a marker name from its axis letter in a header.
AXIS_SEPARATORS = " _.:-"


def split_csv_line(line: str) -> list[str]:
    """Fields of one CSV line (fast path without quotes)."""
    if '"' not in line:
        return line.split(",")
    return next(csv.reader([line]), [])


def _normal(name: str) -> str:
    return re.sub(r"[\s_().\[\]-]", "", name.lower())


def _header_layout(
    source: Path, columns: list[str], line_no: int
) -> tuple[int | None, int | None, list[str], int]:
    """Find frame/time columns and the marker groups; return (frame, time, markers, D)."""
    idx = 0
    frame_col = time_col = None
    if idx < len(columns) and _normal(columns[idx]) in _FRAME_NAMES:
        frame_col, idx = idx, idx + 1
    if idx < len(columns) and _normal(columns[idx]) in _TIME_NAMES:
        time_col, idx = idx, idx + 1
    groups: list[tuple[str, str]] = []  # (name, axes)
    for k in range(idx, len(columns)):
        match = _AXIS.fullmatch(columns[k])
        name = match.group(1).strip() if match else ""
        if not name:
            raise InputError(
                source,
                f"header {columns[k]!r} (column {k + 1}) is not a coordinate column; "
                "expected <Name>X, <Name>Y[, <Name>Z] after optional Frame# and Time columns",
                where=f"line {line_no}",
            )
        axis = match.group(2).upper()
        if groups and groups[-1][0] == name and axis not in groups[-1][1]:
            groups[-1] = (name, groups[-1][1] + axis)
        else:
            groups.append((name, axis))
    if not groups:
        raise InputError(source, "header has no marker coordinate columns", where=f"line {line_no}")
    axes = groups[0][1]
    for name, got in groups:
        if got not in ("XY", "XYZ") or got != axes:
            raise InputError(
                source,
                f"marker {name!r} has columns for axes {', '.join(got)}; expected "
                f"{', '.join(axes if axes in ('XY', 'XYZ') else 'XYZ')} in that order",
                where=f"line {line_no}",
            )
    names = [name for name, _ in groups]
    check_marker_names(str(source), names, where=f"line {line_no}")
    return frame_col, time_col, names, len(axes)


#: Separators other than the comma that a header may use, by how a message names them.
OTHER_SEPARATORS = {";": "';'", "\t": "tabs", "|": "'|'"}


def _check_separator(source: Path, header: str, line_no: int) -> None:
    """Refuse a header row that has no comma but another separator (a semicolon-, tab- or
    bar-separated export, or columns separated by spaces): it would read as one column."""
    if "," in header:
        return
    if header.split("\t", 1)[0].strip() == "PathFileType":
        raise InputError(
            source,
            "this is a TRC file (its header starts with PathFileType), not a comma-separated "
            "CSV: give it the extension .trc",
            where=f"line {line_no}",
        )
    found = [name for sep, name in OTHER_SEPARATORS.items() if sep in header]
    if not found and len(header.split()) >= 3:
        found = ["spaces"]
    if found:
        raise InputError(
            source,
            f"the file seems to use {found[0]} as its separator (the header has no comma); "
            "expected comma-separated columns: Frame#,Time,<Name>X,<Name>Y,<Name>Z,... "
            "(export or save it as CSV with commas)",
            where=f"line {line_no}",
        )


def read_csv(
    path: Path, rate: float | None = None, units: str | None = None, strict: bool = False
) -> Trajectory:
    """Read a wide CSV marker file (see the module docstring for the conventions)."""
    lines, final_newline = read_lines(path)
    meta: dict[str, tuple[str, int]] = {}
    i = 0
    while i < len(lines) and (
        not lines[i].strip() or (lines[i].lstrip().startswith("#") and "," not in lines[i])
    ):
        match = _META.fullmatch(lines[i].strip())
        if match:
            meta[match.group(1).lower()] = (match.group(2), i + 1)
        i += 1
    if i == len(lines):
        raise InputError(
            path,
            f"{'file is empty' if not lines else 'no header line'}; expected Frame#,Time,<Name>X,<Name>Y,<Name>Z,...",
        )
    _check_separator(path, lines[i], i + 1)
    try:
        header_fields = split_csv_line(lines[i])
        columns = [c.strip() for c in header_fields]
        while columns and not columns[-1]:
            columns.pop()
        frame_col, time_col, names, dim = _header_layout(path, columns, i + 1)
        rows = [
            (j + 1, split_csv_line(lines[j])) for j in range(i + 1, len(lines)) if lines[j].strip()
        ]
    except csv.Error as exc:
        raise InputError(path, f"malformed CSV ({exc})") from None
    if not rows:
        raise InputError(path, "no data rows after the header", where=f"line {i + 1}")
    what = incomplete_last_row(rows, len(columns), final_newline)
    last_line = rows[-1][0]
    rows = drop_incomplete_row(path, rows, what, strict)

    in_file, units_line = meta.get("units", (None, 0))
    unit = units_of(path, units, in_file, f"line {units_line}")
    declared = declared_rates(path, rate)
    if "rate" in meta:
        rate_text, line_no = meta["rate"]
        declared.append(
            (
                f"rate comment (line {line_no})",
                positive_rate(rate_text, path, f"line {line_no}: rate"),
            )
        )

    start_col = len(columns) - len(names) * dim
    coord_cols = list(range(start_col, len(columns)))
    ended = final_newline or what is not None  # the rows before a dropped one all ended
    parsed = parse_rows(path, rows, columns, coord_cols, time_col, frame_col, ended)
    trajectory = table_trajectory(path, rows, parsed, declared, names, dim, unit, (what, last_line))
    if units is None and "units" not in meta:
        warn_small_span(path, trajectory.positions)
    return trajectory
