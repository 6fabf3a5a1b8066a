"""Reader for MATLAB ``.mat`` marker exports (Qualisys QTM layout), v5 and v7.3 (HDF5).

QTM's MATLAB export holds one struct, saved under a variable named after the file
(``walk01``), with the fields used here::

    walk01.FrameRate                  sample rate in Hz (scalar)
    walk01.StartFrame                 first frame number, 1-based (optional)
    walk01.Trajectories.Labeled.Data    [markers, 4, frames]: x, y, z, residual
    walk01.Trajectories.Labeled.Labels  1 x markers cell array of names

* The struct is the top-level variable holding a ``Trajectories`` field (the one named
  after the file when there are several), or the file itself when ``Trajectories`` is a
  top-level variable (``save(file, '-struct', 's')``).
* ``Data`` may also be [markers, 3, frames] (no residual); a single frame may be
  [markers, 4] (MATLAB drops trailing singleton dimensions).  ``Labels`` may be a cell
  array of strings or a char matrix (one padded name per row).
* Missing samples: non-finite coordinates (QTM writes gaps as NaN) and a negative
  residual (the C3D convention).
* Units: millimetres (QTM's); the ``units`` argument overrides them.
* Rate: ``FrameRate``; a ``rate`` argument must agree with it within 1 % (and is needed
  when the file has none).  Start time: ``(StartFrame - 1) / rate`` as for C3D, else 0.
* Version 5 (and 4) files are read with :func:`scipy.io.loadmat`; version 7.3 files
  (``save -v7.3``, HDF5 with a 512-byte MATLAB header; scipy refuses them) with ``h5py``:
  arrays there are stored transposed (column-major) and strings as UTF-16 ``uint16``
  arrays behind object references.
* Anything malformed (not a MAT file, corrupt HDF5, missing fields, wrong shapes, a
  label count that differs from the data) is an :class:`InputError` naming the file and
  the field.
"""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np

from activebonds.data._common import (
    declared_rates,
    file_trajectory,
    positive_rate,
    read_bytes,
    reconcile_rates,
    to_metres,
    units_of,
)
from activebonds.data.trajectory import Trajectory, check_marker_names
from activebonds.errors import InputError

_EXPECTED = (
    "expected a QTM MATLAB export: a struct with Trajectories.Labeled.Data "
    "[markers, 4, frames], Trajectories.Labeled.Labels and FrameRate"
)


class _Bad(Exception):
    """Internal: a malformed field (message and field path are user-facing)."""

    def __init__(self, where: str, message: str):
        super().__init__(message)
        self.where = where
        self.message = message


# ----------------------------------------------------------------------------- the two layouts
class _V5:
    """Navigation of :func:`scipy.io.loadmat` output (``squeeze_me=False``, records)."""

    def __init__(self, variables: dict):
        self.top = {k: v for k, v in variables.items() if not k.startswith("__")}

    def is_struct(self, node) -> bool:
        return isinstance(node, dict) or (
            isinstance(node, np.ndarray) and node.dtype.names is not None
        )

    def names(self, node) -> list[str]:
        return list(node) if isinstance(node, dict) else list(node.dtype.names)

    def member(self, node, name: str, where: str):
        if isinstance(node, dict):
            return node[name]
        if node.size != 1:
            raise _Bad(where, f"is a struct array of size {_size(node.shape)}; expected one struct")
        return node.reshape(-1)[0][name]

    def numbers(self, node, where: str) -> np.ndarray:
        if not isinstance(node, np.ndarray) or node.dtype.kind not in "biuf":
            raise _Bad(where, f"expected a numeric array, got {_kind(node)}")
        return node

    def strings(self, node, where: str) -> list[str]:
        if isinstance(node, np.ndarray) and node.dtype.kind == "U":  # char matrix
            return [str(s).rstrip() for s in node.reshape(-1)]
        if not isinstance(node, np.ndarray) or node.dtype.kind != "O":
            raise _Bad(where, f"expected a cell array of names, got {_kind(node)}")
        _check_vector(node.shape, where)
        names = []
        for k, item in enumerate(node.reshape(-1)):
            if isinstance(item, np.ndarray) and item.dtype.kind == "U" and item.size <= 1:
                names.append(str(item.reshape(-1)[0]) if item.size else "")
            else:
                raise _Bad(where, f"cell {k + 1} is {_kind(item)}, expected a string")
        return names


class _V73:
    """Navigation of a MATLAB v7.3 (HDF5) file through ``h5py``."""

    def __init__(self, handle):
        self.top = handle
        self.file = handle

    def is_struct(self, node) -> bool:
        import h5py

        return isinstance(node, h5py.Group)

    def names(self, node) -> list[str]:
        return [k for k in node.keys() if not k.startswith("#")]

    def member(self, node, name: str, where: str):
        try:
            return node[name]
        except Exception as exc:  # broken link, corrupt object header, ...
            raise _Bad(where, f"cannot open the field ({_detail(exc)}); corrupt file?") from None

    def _read(self, node, where: str) -> np.ndarray:
        try:
            return np.asarray(node[()])
        except Exception as exc:  # corrupt chunk, unsupported filter, ...
            raise _Bad(where, f"cannot read the array ({_detail(exc)}); corrupt file?") from None

    def _class(self, node) -> str:
        value = node.attrs.get("MATLAB_class", b"")
        return value.decode("ascii", "replace") if isinstance(value, bytes) else str(value)

    def numbers(self, node, where: str) -> np.ndarray:
        import h5py

        if not isinstance(node, h5py.Dataset):
            raise _Bad(where, "expected a numeric array, got a struct")
        if node.attrs.get("MATLAB_empty", 0):
            return np.zeros((0, 0))
        if node.dtype.kind not in "biuf" or self._class(node) in ("char", "cell", "struct"):
            raise _Bad(where, f"expected a numeric array, got MATLAB class {self._class(node)!r}")
        return self._read(node, where).T  # HDF5 holds MATLAB arrays transposed

    def _text(self, node, where: str) -> list[str]:
        """The rows of a MATLAB char array."""
        if node.attrs.get("MATLAB_empty", 0):
            return [""]
        if self._class(node) != "char" or node.dtype.kind not in "ui":
            raise _Bad(where, f"expected a string, got MATLAB class {self._class(node)!r}")
        codes = np.atleast_2d(self._read(node, where).T)  # MATLAB [rows, chars]
        if codes.ndim != 2:
            raise _Bad(where, f"expected a string, got a char array of shape {codes.shape}")
        return [row.astype("<u2").tobytes().decode("utf-16-le") for row in codes]

    def strings(self, node, where: str) -> list[str]:
        import h5py

        if not isinstance(node, h5py.Dataset):
            raise _Bad(where, "expected a cell array of names, got a struct")
        if self._class(node) == "char":  # char matrix
            return [s.rstrip() for s in self._text(node, where)]
        if node.dtype != h5py.ref_dtype:
            raise _Bad(
                where, f"expected a cell array of names, got MATLAB class {self._class(node)!r}"
            )
        refs = self._read(node, where)
        _check_vector(refs.shape, where)
        names = []
        for k, ref in enumerate(refs.T.reshape(-1)):
            if not ref:
                raise _Bad(where, f"cell {k + 1} is an empty reference, expected a string")
            cell = f"{where}{{{k + 1}}}"
            try:
                target = self.file[ref]
            except Exception as exc:
                raise _Bad(cell, f"cannot follow the reference ({_detail(exc)})") from None
            text = self._text(target, cell)
            if len(text) != 1:
                raise _Bad(where, f"cell {k + 1} holds {len(text)} rows of text, expected one name")
            names.append(text[0])
        return names


def _size(shape) -> str:
    return "x".join(str(n) for n in shape) or "1x1"


def _kind(node) -> str:
    if isinstance(node, np.ndarray):
        return f"an array of dtype {node.dtype} and size {_size(node.shape)}"
    return type(node).__name__


def _check_vector(shape, where: str) -> None:
    if len(shape) > 2 or (len(shape) == 2 and min(shape) > 1):
        raise _Bad(where, f"expected a vector of names, got size {_size(shape)}")


# ----------------------------------------------------------------------------- reading
def _root(layout, stem: str):
    """(struct, its name) of the export: the file itself or a top-level struct variable."""
    names = layout.names(layout.top)
    if "Trajectories" in names:
        return layout.top, ""
    found = [
        n
        for n in names
        if layout.is_struct(node := layout.member(layout.top, n, n))
        and "Trajectories" in layout.names(node)
    ]
    if len(found) > 1 and stem in found:
        found = [stem]
    if len(found) == 1:
        return layout.member(layout.top, found[0], found[0]), found[0]
    if found:
        raise _Bad(
            "",
            f"several variables hold a Trajectories struct ({', '.join(found)}) and none "
            "is named after the file; keep one",
        )
    listed = ", ".join(names[:10]) + (", ..." if len(names) > 10 else "")
    raise _Bad("", f"no Trajectories struct (variables: {listed or 'none'}); {_EXPECTED}")


def _field(layout, node, path: list[str], prefix: str):
    """The member at ``path`` below ``node`` (every step but the last a struct)."""
    where = prefix
    for name in path:
        if not layout.is_struct(node):
            raise _Bad(where, f"is not a struct, so it has no field {name}; {_EXPECTED}")
        where = f"{where}.{name}" if where else name
        if name not in layout.names(node):
            raise _Bad(where, f"field is missing; {_EXPECTED}")
        node = layout.member(node, name, where)
    return node, where


def _scalar(layout, node, where: str) -> float:
    value = layout.numbers(node, where)
    if value.size != 1:
        raise _Bad(where, f"expected a single number, got size {_size(value.shape)}")
    return float(value.reshape(-1)[0])


def _extract(layout, stem: str) -> tuple:
    """(data [markers, C, frames], labels, rate or None, start frame or None, field of Data)."""
    root, prefix = _root(layout, stem)
    node, where = _field(layout, root, ["Trajectories", "Labeled", "Data"], prefix)
    data = layout.numbers(node, where)
    if data.ndim == 2 and data.shape[1] in (3, 4):
        data = data[:, :, None]  # one frame: MATLAB dropped the trailing 1
    if data.ndim != 3 or data.shape[1] not in (3, 4) or min(data.shape) < 1:
        raise _Bad(
            where,
            f"expected [markers, 4, frames] (x, y, z, residual), got size {_size(data.shape)}",
        )
    node, labels_where = _field(layout, root, ["Trajectories", "Labeled", "Labels"], prefix)
    labels = layout.strings(node, labels_where)
    if len(labels) != data.shape[0]:
        raise _Bad(labels_where, f"has {len(labels)} names but {where} has {data.shape[0]} markers")
    rate = start = None
    if "FrameRate" in layout.names(root):
        node, rate_where = _field(layout, root, ["FrameRate"], prefix)
        rate = (_scalar(layout, node, rate_where), rate_where)
    if "StartFrame" in layout.names(root):
        node, start_where = _field(layout, root, ["StartFrame"], prefix)
        start = (_scalar(layout, node, start_where), start_where)
    return np.array(data, dtype=np.float64), labels, rate, start, where


def _load(path: Path, data: bytes) -> tuple:
    """Open the file with scipy (v4/v5) or h5py (v7.3) and extract the export's arrays."""
    import scipy.io

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            variables = scipy.io.loadmat(io.BytesIO(data), squeeze_me=False)
    except NotImplementedError:  # v7.3: HDF5
        return _load_hdf5(path, data)
    except Exception as exc:  # MatReadError, ValueError, zlib/struct errors, ...
        if data[:8] == b"\x89HDF\r\n\x1a\n":  # HDF5 without a MATLAB header
            return _load_hdf5(path, data)
        raise InputError(path, f"not a readable MAT file ({_detail(exc)}); {_EXPECTED}") from None
    return _extract(_V5(variables), path.stem)


def _load_hdf5(path: Path, data: bytes) -> tuple:
    import h5py

    try:
        handle = h5py.File(io.BytesIO(data), "r")
    except Exception as exc:
        raise InputError(
            path, f"not a readable MAT v7.3 (HDF5) file ({_detail(exc)}); {_EXPECTED}"
        ) from None
    with handle:
        return _extract(_V73(handle), path.stem)


def _detail(exc: BaseException) -> str:
    text = " ".join(str(exc).split())[:120]
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def read_mat(
    path: Path, rate: float | None = None, units: str | None = None, strict: bool = False
) -> Trajectory:
    """Read a QTM MATLAB export (see the module docstring); ``strict`` has no effect."""
    data = read_bytes(path)
    try:
        points, labels, file_rate, start_frame, where = _load(path, data)
    except _Bad as exc:
        raise InputError(path, exc.message, where=exc.where or None) from None
    except InputError:
        raise
    except Exception as exc:  # h5py/scipy on a corrupt file raise anything
        raise InputError(path, f"corrupt MAT file ({_detail(exc)}); {_EXPECTED}") from None
    check_marker_names(str(path), labels, where=where.replace(".Data", ".Labels"))
    declared = declared_rates(path, rate)
    if file_rate is not None:
        declared.append((file_rate[1], positive_rate(file_rate[0], path, file_rate[1])))
    sample_rate = reconcile_rates(path, declared)
    if sample_rate is None:
        raise InputError(path, "no FrameRate in the file; pass the sample rate in Hz")
    start = 0.0
    if start_frame is not None:
        first, start_where = start_frame
        if not (np.isfinite(first) and first == int(first)):
            raise InputError(path, f"expected a whole frame number, got {first!r}", start_where)
        start = (first - 1) / sample_rate
    unit = units_of(path, units)
    xyz = points[:, :3, :].transpose(2, 0, 1)  # [frames, markers, 3]
    mask = np.all(np.isfinite(xyz), axis=-1)
    if points.shape[1] == 4:
        mask &= ~(points[:, 3, :].T < 0)
    positions = to_metres(xyz.copy(), unit)
    positions[~mask] = np.nan
    if not np.all(np.isfinite(positions[mask])):
        raise InputError(path, "coordinates overflow when converted to metres", where=where)
    return file_trajectory(path, positions, mask, labels, sample_rate, start, unit)
