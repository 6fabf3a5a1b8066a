"""Reader for OpenSim TRC marker files (5 header lines, tab or space separated).

::

    PathFileType  4  (X/Y/Z)  walk.trc
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  ...
    60.00     60.00       151        41          mm     60.00         ...
    Frame#  Time  R.ASIS        L.ASIS  ...
                  X1  Y1  Z1    X2  Y2  Z2  ...
    <optional blank line>
    1  0.000000  617.24762  1055.27502  170.78198  ...

* Separators: tabs (OpenSim), runs of tabs ("double tabs") or spaces, in the header and
  in the data.  Header keys (line 2) are paired with values (line 3) by position: by tab
  when both lines have the same number of tab fields (so a blank value keeps its place),
  else by words.  Marker names (line 4) are the non-blank tab fields, or else the words,
  whichever gives NumMarkers names (names with spaces need tabs); they are matched to
  columns by order, three per marker, and line 5 must hold 3 x NumMarkers labels.
* DataRate, NumFrames, NumMarkers and Units are required; counts may be written as
  integral decimals ("100.0").  The rate is DataRate (a ``rate`` argument must agree
  with it within 1 %) and DataRate is checked against the time column (> 1 %
  disagreement is an error; so are missing or duplicated rows).
* Units: the ``units`` argument overrides the Units header (mm, cm, m).
* Data rows: a row with tabs is split on each tab (blank fields and ``nan`` are missing
  samples; trailing tabs are ignored), unless that leaves values beyond the header's
  columns, when it is split on runs of blanks (double tabs); a row without tabs is split
  on runs of spaces.
* A row with fewer fields than the header is an error naming its line, and so is a row
  count different from NumFrames, except for an incomplete **last** row (an interrupted
  export, see :func:`~activebonds.data._common.incomplete_last_row`): it is dropped with
  a :class:`~activebonds.data._common.TruncatedRowWarning` naming the line, and NumFrames
  may then count it or not.  With ``strict=True`` it is an error naming the line.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from activebonds.data._common import declared_rates, positive_rate, units_of
from activebonds.data._table import (
    drop_incomplete_row,
    incomplete_last_row,
    parse_rows,
    read_lines,
    table_trajectory,
)
from activebonds.data.trajectory import Trajectory, check_marker_names
from activebonds.errors import InputError

REQUIRED_KEYS = ("DataRate", "NumFrames", "NumMarkers", "Units")

_BLANKS = re.compile(r"[ \t]+")


def _words(line: str) -> list[str]:
    """The fields of a line separated by runs of spaces and tabs."""
    return [word for word in _BLANKS.split(line) if word]


def _header(path: Path, key_line: str, value_line: str) -> dict[str, str]:
    """Header keys (line 2) paired with their values (line 3)."""
    keys, values = key_line.split("\t"), value_line.split("\t")
    tabbed = "\t" in key_line and "\t" in value_line
    if not (tabbed and len(keys) == len(values)):
        words = _words(key_line), _words(value_line)
        if len(words[0]) == len(words[1]) or not tabbed:
            keys, values = words
    keys = [k.strip(" \t") for k in keys]
    values = [v.strip(" \t") for v in values]
    meta = {k: v for k, v in zip(keys, values, strict=False) if k}
    for key in REQUIRED_KEYS:
        if key not in keys:
            raise InputError(path, f"header key {key} is missing", where="line 2")
        if key not in meta:
            n_keys, n_values = sum(1 for k in keys if k), sum(1 for v in values if v)
            raise InputError(
                path,
                f"header key {key} has no value (line 2 has {n_keys} keys, line 3 has "
                f"{n_values} values)",
                where="line 3",
            )
    return meta


def _count(path: Path, meta: dict[str, str], key: str) -> int:
    text = meta[key]
    try:
        value = int(text)
    except ValueError:
        try:
            number = float(text)
        except ValueError:
            number = math.nan
        if not (math.isfinite(number) and number.is_integer()):
            raise InputError(
                path, f"{key} {text!r} is not a whole number", where="line 3"
            ) from None
        value = int(number)
    if value < 1:
        raise InputError(path, f"{key} must be at least 1, got {value}", where="line 3")
    return value


def _marker_names(path: Path, line: str, n_markers: int) -> list[str]:
    words = _words(line)
    if len(words) < 2 or words[0].lower() != "frame#" or words[1].lower() != "time":
        raise InputError(path, "expected the columns Frame#, Time, <marker names>", where="line 4")
    fields = [f.strip(" \t") for f in line.split("\t")]
    fields = [f for f in fields if f]
    by_tab = fields[2:] if [f.lower() for f in fields[:2]] == ["frame#", "time"] else None
    candidates = ([by_tab] if by_tab is not None and "\t" in line else []) + [words[2:]]
    for names in candidates:
        if len(names) == n_markers:
            check_marker_names(str(path), names, where="line 4")
            return names
    raise InputError(
        path,
        f"line names {len(candidates[0])} markers but NumMarkers is {n_markers}",
        where="line 4",
    )


def _fields(line: str, n_fields: int) -> list[str]:
    """The fields of one data row (see the module docstring)."""
    if "\t" in line:
        fields = line.split("\t")
        if len(fields) <= n_fields or not any(f.strip() for f in fields[n_fields:]):
            return fields
    return _words(line)


def read_trc(
    path: Path, rate: float | None = None, units: str | None = None, strict: bool = False
) -> Trajectory:
    """Read an OpenSim TRC file (see the module docstring)."""
    lines, final_newline = read_lines(path)
    if not any(line.strip() for line in lines):
        raise InputError(path, "file is empty; expected an OpenSim TRC file")
    if len(lines) < 5:
        raise InputError(path, f"only {len(lines)} lines; a TRC file has 5 header lines and data")
    first = _words(lines[0])
    if not first or first[0] != "PathFileType":
        found = repr(first[0][:40]) if first else "an empty line"
        raise InputError(
            path, f"not a TRC file: expected 'PathFileType' first, found {found}", where="line 1"
        )
    meta = _header(path, lines[1], lines[2])
    data_rate = positive_rate(meta["DataRate"], path, "line 3: DataRate")
    n_frames = _count(path, meta, "NumFrames")
    n_markers = _count(path, meta, "NumMarkers")
    unit = units_of(path, units, meta["Units"], "line 3: Units")
    names = _marker_names(path, lines[3], n_markers)
    axes = _words(lines[4])
    if len(axes) != 3 * n_markers:
        raise InputError(
            path,
            f"expected {3 * n_markers} coordinate labels (X1 Y1 Z1 ...), found {len(axes)}",
            where="line 5",
        )

    columns = ["Frame#", "Time"] + [f"{n} {a}" for n in names for a in "XYZ"]
    rows = [
        (j + 1, _fields(lines[j], len(columns))) for j in range(5, len(lines)) if lines[j].strip()
    ]
    what = incomplete_last_row(rows, len(columns), final_newline)
    if what is None and len(rows) != n_frames:
        raise InputError(
            path,
            f"header declares NumFrames {n_frames} but the file has {len(rows)} data rows "
            "(truncated or edited file?)",
        )
    if what is not None and not strict and n_frames not in (len(rows) - 1, len(rows)):
        raise InputError(
            path,
            f"header declares NumFrames {n_frames} but the file has {len(rows) - 1} complete "
            f"data rows and an incomplete last row (line {rows[-1][0]}; truncated or edited "
            "file?)",
        )
    last_line = rows[-1][0] if rows else 0
    rows = drop_incomplete_row(path, rows, what, strict)
    coord_cols = list(range(2, len(columns)))
    ended = final_newline or what is not None  # the rows before a dropped one all ended
    parsed = parse_rows(path, rows, columns, coord_cols, 1, 0, ended)
    declared = declared_rates(path, rate, ("DataRate", data_rate))
    return table_trajectory(path, rows, parsed, declared, names, 3, unit, (what, last_line))
