"""Helpers shared by the trajectory readers and writers: units, sample rates, numbers, files.

Everything here raises :class:`activebonds.errors.InputError` naming the file at fault.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np

from activebonds.data.trajectory import Trajectory
from activebonds.errors import InputError

#: Length units understood in trajectory files: how many of them make a metre.
PER_METRE = {"mm": 1000.0, "cm": 100.0, "m": 1.0}

_UNIT_ALIASES = {
    "mm": "mm",
    "millimeter": "mm",
    "millimeters": "mm",
    "millimetre": "mm",
    "millimetres": "mm",
    "cm": "cm",
    "centimeter": "cm",
    "centimeters": "cm",
    "centimetre": "cm",
    "centimetres": "cm",
    "m": "m",
    "meter": "m",
    "meters": "m",
    "metre": "m",
    "metres": "m",
}

#: Relative disagreement between two sample rates that is reported as an error.
RATE_TOLERANCE = 0.01


def canonical_units(source: str | Path, units: object, where: str | None = None) -> str:
    """Return "mm", "cm" or "m" for a unit name (case and spelling tolerant), else InputError."""
    name = str(units).strip().lower() if isinstance(units, str) else None
    if name not in _UNIT_ALIASES:
        raise InputError(
            source, f"unknown length unit {units!r}; expected one of mm, cm, m", where=where
        )
    return _UNIT_ALIASES[name]


def to_metres(values: np.ndarray, units: str) -> np.ndarray:
    """Convert an array in ``units`` (canonical name) to metres.

    Divides (955.40527 mm / 1000 is the double nearest 0.95540527 m; multiplying by 1e-3
    is not always).  Metres are returned unchanged (same array).
    """
    if units == "m":
        return values
    return values / PER_METRE[units]


def positive_rate(value: object, source: str | Path, what: str) -> float:
    """Check that a sample rate is a finite positive number and return it as float."""
    try:
        rate = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(
            source, f"{what} {value!r} is not a number; expected a rate in Hz"
        ) from None
    if not math.isfinite(rate) or rate <= 0:
        raise InputError(source, f"{what} {value!r} must be a positive finite rate in Hz")
    return rate


def declared_rates(
    source: str | Path, rate: object | None, *in_file: tuple[str, float]
) -> list[tuple[str, float]]:
    """The rates a reader checks against each other: the ``rate`` given to it (``"sample
    rate"``, checked by :func:`positive_rate`) if any, first, then the file's own ``in_file``
    (description, rate) pairs."""
    given = [] if rate is None else [("sample rate", positive_rate(rate, source, "sample rate"))]
    return given + list(in_file)


def agreed_rate(
    source: str | Path, rate: object | None, *in_file: tuple[str, float]
) -> float | None:
    """The sample rate of a file read whole: the first of :func:`declared_rates` once they
    all agree (:func:`reconcile_rates`)."""
    return reconcile_rates(source, declared_rates(source, rate, *in_file))


def units_of(
    source: str | Path,
    option: str | None,
    in_file: object | None = None,
    where: str | None = None,
    default: str = "mm",
) -> str:
    """The canonical length unit of a file: the ``units`` option's if given, else the file's
    own (``in_file``, found at ``where``) if it has one, else ``default``."""
    if option is not None:
        return canonical_units(source, option, where="units option")
    if in_file is not None:
        return canonical_units(source, in_file, where=where)
    return default


def reconcile_rates(source: str | Path, declared: list[tuple[str, float]]) -> float | None:
    """Return the first declared rate after checking that all declared rates agree (1 %)."""
    if not declared:
        return None
    first_label, first = declared[0]
    for label, rate in declared[1:]:
        if abs(rate - first) > RATE_TOLERANCE * rate:
            raise InputError(
                source, f"{first_label} {first:g} Hz disagrees with {label} ({rate:g} Hz)"
            )
    return first


def read_text(path: Path) -> str:
    """Read a UTF-8 (optionally BOM-prefixed) text file, or raise InputError."""
    data = read_bytes(path)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError(
            path,
            f"not a UTF-8 text file (byte 0x{data[exc.start]:02x} at offset {exc.start})",
            where=f"line {line}",
        ) from None


def read_bytes(path: Path) -> bytes:
    """Read a whole file, turning OS errors into InputError."""
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise InputError(path, "file not found") from None
    except IsADirectoryError:
        raise InputError(path, "is a directory, expected a trajectory file") from None
    except OSError as exc:
        raise InputError(path, f"cannot read file ({exc.strerror or exc})") from None


class FileWarning(UserWarning):
    """A doubt about a trajectory file that does not stop the reading: one line, ``FILE:
    [line N: ]what``, like an :class:`~activebonds.errors.InputError` (the command line prints
    it as ``warning: ...``)."""

    def __init__(self, source: str | Path, message: str, line: int | None = None):
        self.source = str(source)
        self.line = line
        where = f"line {line}" if line is not None else None
        super().__init__(InputError(source, message, where=where).line())


class TruncatedRowWarning(FileWarning):
    """The last data row of a text trajectory file was incomplete and has been dropped.

    ``source`` and ``line`` hold the file and the line number. ``strict=True`` turns the same
    finding into an InputError.
    """

    def __init__(self, source: str | Path, line: int, message: str):
        super().__init__(source, message, line)


class UnitsWarning(FileWarning):
    """A file without a units line, read as millimetres, whose markers span so little that
    it is more likely in metres (or centimetres)."""


#: A recording read as millimetres by default that spans less than this (m) is doubted.
SMALL_SPAN = 0.01


def warn_small_span(source: str | Path, positions: np.ndarray) -> None:
    """The :class:`UnitsWarning` of a file of two markers or more, read as millimetres without
    a units line, whose markers span less than :data:`SMALL_SPAN` on every axis (no
    motion-capture marker set is that small; a body in metres read as millimetres spans one
    or two)."""
    x = np.asarray(positions, np.float64)
    if x.shape[1] < 2 or not np.isfinite(x).any():
        return  # one marker's path says nothing of a body's size
    span = float(np.max(np.nanmax(x, axis=(0, 1)) - np.nanmin(x, axis=(0, 1))))
    if span < SMALL_SPAN:
        warnings.warn(
            UnitsWarning(
                source,
                f"no units line, so read as millimetres, and the markers span only "
                f"{span * 1000:.3g} mm: if the file is in metres, add the line '# units: m' "
                "(or cm) above the header",
            ),
            stacklevel=4,
        )


def by_extension(table: dict, path: Path):
    """The entry of ``table`` (a reader or a writer per file extension) for ``path``'s
    extension; an :class:`InputError` naming the extensions known otherwise."""
    entry = table.get(path.suffix.lower())
    if entry is None:
        raise InputError(
            path,
            f"unknown trajectory file extension {path.suffix or '(none)'!r}; "
            f"expected one of {', '.join(table)}",
        )
    return entry


def check_output_path(path: Path) -> None:
    """A writer's target must be in an existing folder and must not be a folder itself."""
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(path, f"output folder {str(parent)!r} does not exist")
    if path.is_dir():
        raise InputError(path, "is a directory, expected a file name")


def file_trajectory(
    source: Path,
    positions: np.ndarray,
    mask: np.ndarray,
    markers: list[str] | tuple[str, ...],
    rate: float,
    start_time: float,
    units: str,
) -> Trajectory:
    """The :class:`Trajectory` a reader returns: ``positions`` in metres, read from the file
    ``source`` written in ``units``."""
    return Trajectory(
        positions=positions,
        mask=mask,
        markers=tuple(markers),
        rate=rate,
        start_time=start_time,
        source_units=units,
        source=str(source),
    )
