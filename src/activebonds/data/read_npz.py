"""Reader for NumPy ``.npz`` trajectory archives (always ``allow_pickle=False``).

Keys: ``positions`` [frames, markers, D] (numbers), ``markers`` (1-D string array),
``rate`` (scalar, Hz); optional ``mask`` [frames, markers] (bool or 0/1; default: all
present), ``units`` (string, default "m"; the ``units`` argument overrides it) and
``start_time`` (scalar seconds, default 0).  NaN samples are missing; masked samples may
hold any value (they become NaN).  Object (pickled) arrays are refused.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from activebonds.data._common import (
    agreed_rate,
    file_trajectory,
    positive_rate,
    read_bytes,
    to_metres,
    units_of,
)
from activebonds.data.trajectory import Trajectory, check_marker_names
from activebonds.errors import InputError

_KEYS = "positions, markers, rate [, mask, units, start_time]"


def _get(path: Path, archive, key: str, required: bool = True) -> np.ndarray | None:
    if key not in archive.files:
        if required:
            raise InputError(path, f"key {key!r} is missing; expected keys {_KEYS}")
        return None
    try:
        return archive[key]
    except ValueError as exc:
        if "allow_pickle" in str(exc) or "Object arrays" in str(exc):
            raise InputError(
                path,
                "holds Python objects (pickled data), which are refused; use plain arrays",
                where=key,
            ) from None
        raise InputError(
            path, f"cannot read array ({' '.join(str(exc).split())[:100]})", key
        ) from None
    except Exception as exc:  # zip/zlib/format errors from a corrupt member
        raise InputError(path, f"cannot read array ({type(exc).__name__})", where=key) from None


def _scalar(path: Path, value: np.ndarray, key: str, kinds: str) -> object:
    if value.size != 1 or value.dtype.kind not in kinds:
        raise InputError(
            path,
            f"expected a single {'string' if kinds == 'US' else 'number'}, "
            f"got dtype {value.dtype} shape {value.shape}",
            where=key,
        )
    item = value.reshape(()).item()
    if isinstance(item, bytes):
        try:
            item = item.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(path, "string is not valid UTF-8", where=key) from None
    return item


def _load(path: Path):
    data = read_bytes(path)  # in memory: np.load leaks its handle on a corrupt archive
    try:
        archive = np.load(io.BytesIO(data), allow_pickle=False)
    except Exception as exc:  # BadZipFile, ValueError (pickle), OSError, EOFError, ...
        raise InputError(
            path, f"not a readable .npz archive ({type(exc).__name__}); expected keys {_KEYS}"
        ) from None
    if not isinstance(archive, np.lib.npyio.NpzFile):
        raise InputError(path, f"holds a single array, expected an .npz archive with keys {_KEYS}")
    return archive


def read_npz(path: Path, rate: float | None = None, units: str | None = None) -> Trajectory:
    """Read an .npz trajectory archive (see the module docstring)."""
    with _load(path) as archive:
        positions = _get(path, archive, "positions")
        markers = _get(path, archive, "markers")
        rate_value = _get(path, archive, "rate")
        mask = _get(path, archive, "mask", required=False)
        units_value = _get(path, archive, "units", required=False)
        start_value = _get(path, archive, "start_time", required=False)

    if positions.dtype.kind not in "fiu" or positions.ndim != 3 or min(positions.shape) < 1:
        raise InputError(
            path,
            f"expected a numeric array [frames, markers, D], got dtype {positions.dtype} "
            f"shape {positions.shape}",
            where="positions",
        )
    if markers.dtype.kind not in "US" or markers.ndim != 1 or len(markers) != positions.shape[1]:
        raise InputError(
            path,
            f"expected {positions.shape[1]} marker names (1-D string array), got dtype "
            f"{markers.dtype} shape {markers.shape}",
            where="markers",
        )
    try:
        names = tuple(
            m.decode("utf-8") if isinstance(m, bytes) else str(m) for m in markers.tolist()
        )
    except UnicodeDecodeError:
        raise InputError(path, "marker names are not valid UTF-8", where="markers") from None
    check_marker_names(str(path), names, where="markers")
    file_rate = positive_rate(_scalar(path, rate_value, "rate", "fiu"), path, "rate")
    sample_rate = agreed_rate(path, rate, ("rate in the file", file_rate))
    if units is None and units_value is not None:  # the file's, checked only when it is read
        units_value = _scalar(path, units_value, "units", "US")
    unit = units_of(path, units, units_value, "units", default="m")
    start = 0.0
    if start_value is not None:
        start = float(_scalar(path, start_value, "start_time", "fiu"))
        if not np.isfinite(start):
            raise InputError(path, f"must be a finite number, got {start}", where="start_time")

    values = positions.astype(np.float64)
    present = np.all(~np.isnan(values), axis=-1)
    if mask is not None:
        if mask.shape != positions.shape[:2] or mask.dtype.kind not in "biu":
            raise InputError(
                path,
                f"expected a boolean array of shape {positions.shape[:2]}, got dtype "
                f"{mask.dtype} shape {mask.shape}",
                where="mask",
            )
        if mask.dtype.kind != "b" and not np.isin(mask, (0, 1)).all():
            raise InputError(path, "integer mask must hold only 0 and 1", where="mask")
        present &= mask.astype(bool)
    if np.isinf(values[present]).any():
        raise InputError(path, "present samples must be finite (found inf)", where="positions")
    values = to_metres(values, unit)
    if not np.all(np.isfinite(values[present])):
        raise InputError(path, "values overflow when converted to metres", where="positions")
    values[~present] = np.nan
    return file_trajectory(path, values, present, names, sample_rate, start, unit)
