"""Reader for OpenSim TRC marker files (tab separated, 5 header lines).

::

    PathFileType  4  (X/Y/Z)  walk.trc
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  ...
    60.00     60.00       151        41          mm     60.00         ...
    Frame#  Time  R.ASIS        L.ASIS  ...
                  X1  Y1  Z1    X2  Y2  Z2  ...
    <optional blank line>
    1  0.000000  617.24762  1055.27502  170.78198  ...

* DataRate, NumFrames, NumMarkers and Units are required.  The rate is DataRate (a
  ``rate`` argument must agree with it within 1 %) and DataRate is checked against the
  time column (> 1 % disagreement is an error; so are missing or duplicated rows).
* Units: the ``units`` argument overrides the Units header (mm, cm, m).
* Blank fields and ``nan`` are missing samples; trailing tabs are ignored.  A row with
  fewer fields than the header (truncated file) is an error naming its line, and so is a
  row count different from NumFrames.
"""

from __future__ import annotations

from pathlib import Path

from activebonds.data._common import (
    canonical_units,
    data_lines,
    masked_positions,
    parse_rows,
    positive_rate,
    read_text,
    resolve_rate,
)
from activebonds.data._common import (
    ends_with_line_break as _ends_line,
)
from activebonds.data.trajectory import Trajectory, check_marker_names
from activebonds.errors import InputError

REQUIRED_KEYS = ("DataRate", "NumFrames", "NumMarkers", "Units")


def _count(path: Path, meta: dict[str, str], key: str) -> int:
    text = meta[key].strip()
    try:
        value = int(text)
    except ValueError:
        raise InputError(path, f"{key} {text!r} is not a whole number", where="line 3") from None
    if value < 1:
        raise InputError(path, f"{key} must be at least 1, got {value}", where="line 3")
    return value


def _marker_names(path: Path, line: str, n_markers: int) -> list[str]:
    fields = [f.strip() for f in line.split("\t")]
    if len(fields) < 2 or fields[0].lower() != "frame#" or fields[1].lower() != "time":
        raise InputError(path, "expected the columns Frame#, Time, <marker names>", where="line 4")
    named = [(k, name) for k, name in enumerate(fields[2:]) if name]
    names = [name for _, name in named]
    if len(names) != n_markers:
        raise InputError(
            path, f"line names {len(names)} markers but NumMarkers is {n_markers}", where="line 4"
        )
    for slot, (k, name) in enumerate(named):
        if k != 3 * slot:
            raise InputError(
                path,
                f"marker {name!r} is not in column {3 + 3 * slot} (3 columns per marker)",
                where="line 4",
            )
    check_marker_names(str(path), names, where="line 4")
    return names


def read_trc(path: Path, rate: float | None = None, units: str | None = None) -> Trajectory:
    """Read an OpenSim TRC file (see the module docstring)."""
    text = read_text(path)
    lines = data_lines(text)
    if not text.strip():
        raise InputError(path, "file is empty; expected an OpenSim TRC file")
    if len(lines) < 5:
        raise InputError(path, f"only {len(lines)} lines; a TRC file has 5 header lines and data")
    if lines[0].split("\t")[0].strip() != "PathFileType":
        raise InputError(path, "not a TRC file: expected 'PathFileType' first", where="line 1")
    keys = [k.strip() for k in lines[1].split("\t")]
    values = lines[2].split("\t")
    meta = {k: v for k, v in zip(keys, values, strict=False) if k}
    for key in REQUIRED_KEYS:
        if key not in meta:
            raise InputError(path, f"header key {key} is missing", where="line 2")
    data_rate = positive_rate(meta["DataRate"].strip(), path, "line 3: DataRate")
    n_frames = _count(path, meta, "NumFrames")
    n_markers = _count(path, meta, "NumMarkers")
    if units is not None:
        unit = canonical_units(path, units, where="units option")
    else:
        unit = canonical_units(path, meta["Units"], where="line 3: Units")
    names = _marker_names(path, lines[3], n_markers)
    axes = [f for f in lines[4].split("\t") if f.strip()]
    if len(axes) != 3 * n_markers:
        raise InputError(
            path,
            f"expected {3 * n_markers} coordinate labels (X1 Y1 Z1 ...), found {len(axes)}",
            where="line 5",
        )

    columns = ["Frame#", "Time"] + [f"{n} {a}" for n in names for a in "XYZ"]
    rows = [(j + 1, lines[j].split("\t")) for j in range(5, len(lines)) if lines[j].strip()]
    if len(rows) != n_frames:
        raise InputError(
            path,
            f"header declares NumFrames {n_frames} but the file has {len(rows)} data rows "
            "(truncated or edited file?)",
        )
    coord_cols = list(range(2, len(columns)))
    values_, time_strings = parse_rows(path, rows, columns, coord_cols, 1, 0, _ends_line(text))
    declared = [("DataRate", data_rate)]
    if rate is not None:
        declared.insert(0, ("sample rate", positive_rate(rate, path, "sample rate")))
    sample_rate, start_time = resolve_rate(path, declared, time_strings, [n for n, _ in rows])
    positions, mask = masked_positions(values_, n_markers, 3, unit)
    return Trajectory(
        positions=positions,
        mask=mask,
        markers=tuple(names),
        rate=sample_rate,
        start_time=start_time,
        source_units=unit,
        source=str(path),
    )
