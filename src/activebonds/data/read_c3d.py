"""Reader for C3D files through the pure-Python ``c3d`` package (no C code to crash on).

* Points whose residual word is negative (the C3D "invalid / occluded" flag, coordinates
  zero-filled) and non-finite points are missing.
* Units from POINT:UNITS (mm when absent); the ``units`` argument overrides it.
* Rate from the header point rate (cross-checked with POINT:RATE when present); a
  ``rate`` argument must agree with it within 1 %.  The float32 rate is rounded to its
  shortest decimal form (59.94 Hz stays 59.94, not 59.939998626...).
* Start time = (first frame - 1) / rate.
* Corrupt files: the declared frame count times the frame size is checked against the
  file size before reading (so a header declaring billions of frames fails at once), and
  any exception or warning from the library becomes an :class:`InputError`.
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np

from activebonds.data._common import (
    RATE_TOLERANCE,
    agreed_rate,
    file_trajectory,
    read_bytes,
    to_metres,
    units_of,
)
from activebonds.data.trajectory import Trajectory, check_marker_names
from activebonds.errors import InputError


class _Corrupt(Exception):
    """Internal: a consistency check failed (message is user-facing)."""


def _float32_rate(value: float) -> float:
    return float(str(np.float32(value)))


def _labels(reader, n_points: int) -> list[str]:
    labels: list[str] = []
    for key in ["POINT:LABELS"] + [f"POINT:LABELS{k}" for k in range(2, 100)]:
        param = reader.get(key)
        if param is None:
            break
        labels.extend(str(x) for x in np.atleast_1d(param.string_array).ravel())
    if len(labels) < n_points:
        raise _Corrupt(f"POINT:LABELS has {len(labels)} names for {n_points} points")
    return [label.strip() for label in labels[:n_points]]


def _rate(reader) -> float:
    rate = float(reader.header.frame_rate)
    if not np.isfinite(rate) or rate <= 0:
        raise _Corrupt(f"header point rate {rate!r} is not a positive number")
    param = reader.get("POINT:RATE")
    if param is not None:
        declared = float(param.float_value)
        if not abs(declared - rate) <= RATE_TOLERANCE * rate:
            raise _Corrupt(f"header point rate {rate:g} Hz disagrees with POINT:RATE {declared:g}")
    return _float32_rate(rate)


def _check_prefix(path: Path, data: bytes) -> None:
    """Header magic and processor type, checked before the library sees the file."""
    if len(data) < 512:
        raise InputError(path, f"only {len(data)} bytes; a C3D file starts with a 512-byte header")
    if data[1] != 0x50:
        raise InputError(path, f"not a C3D file (second byte is 0x{data[1]:02x}, expected 0x50)")
    processor_at = (data[0] - 1) * 512 + 3
    if data[0] < 1 or processor_at >= len(data):
        raise InputError(path, f"corrupt C3D file: parameter block {data[0]} is outside the file")
    if data[processor_at] not in (84, 85, 86):
        raise InputError(
            path,
            f"corrupt C3D file: unknown processor type {data[processor_at]} "
            "(expected 84 Intel, 85 DEC or 86 MIPS)",
        )


def _read(handle, size: int) -> tuple:
    import c3d  # local: keep the import cost out of text-only use

    reader = c3d.Reader(handle)
    n_points = int(reader.point_used)
    n_frames = int(reader.frame_count)
    if n_points < 1:
        raise _Corrupt("the file holds no 3D points (POINT:USED is 0)")
    if n_frames < 1:
        raise _Corrupt(f"declared frame range gives {n_frames} frames")
    word = 4 if reader.point_scale < 0 else 2
    analog = int(reader.analog_used) * int(reader.analog_per_frame)
    if analog < 0:
        raise _Corrupt(f"negative analog sample count {analog} per frame")
    frame_bytes = 4 * n_points * word + analog * word
    data_start = (int(reader.header.data_block) - 1) * 512
    needed = data_start + n_frames * frame_bytes
    if needed > size:
        raise _Corrupt(
            f"declares {n_frames} frames of {n_points} points ({needed} bytes) but the file "
            f"has {size} bytes (truncated or corrupt)"
        )
    rate = _rate(reader)
    labels = _labels(reader, n_points)
    units_param = reader.get("POINT:UNITS")
    units = units_param.string_value.strip() if units_param is not None else "mm"
    first = int(reader.first_frame)
    points = np.empty((n_frames, n_points, 4), dtype=np.float64)
    count = 0
    for _, frame_points, _ in reader.read_frames(copy=False):
        if count >= n_frames:
            raise _Corrupt("more frames than declared")
        points[count] = frame_points[:, :4]
        count += 1
    if count != n_frames:
        raise _Corrupt(f"declares {n_frames} frames but only {count} could be read")
    return points, labels, rate, units, first


def read_c3d(path: Path, rate: float | None = None, units: str | None = None) -> Trajectory:
    """Read a C3D file (see the module docstring)."""
    data = read_bytes(path)  # also reports missing files uniformly
    _check_prefix(path, data)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            points, labels, file_rate, file_units, first = _read(io.BytesIO(data), len(data))
    except _Corrupt as exc:
        raise InputError(path, f"corrupt C3D file: {exc}") from None
    except InputError:
        raise
    except Exception as exc:  # the library raises anything on corrupt input
        detail = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise InputError(
            path, f"not a readable C3D file ({type(exc).__name__}: {detail})"
        ) from None
    check_marker_names(str(path), labels, where="POINT:LABELS")
    sample_rate = agreed_rate(path, rate, ("header point rate", file_rate))
    unit = units_of(path, units, file_units, "POINT:UNITS")
    mask = (points[:, :, 3] >= 0) & np.all(np.isfinite(points[:, :, :3]), axis=-1)
    positions = to_metres(points[:, :, :3].copy(), unit)
    positions[~mask] = np.nan
    if not np.all(np.isfinite(positions[mask])):
        raise InputError(path, "point coordinates overflow when converted to metres")
    start = (first - 1) / sample_rate
    return file_trajectory(path, positions, mask, labels, sample_rate, start, unit)
