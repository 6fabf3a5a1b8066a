"""``read_trajectory``: one entry point for every supported trajectory file format.

The format is chosen by the file extension (case-blind):

==========  ==================================================  =====================
extension   format                                              units in the file
==========  ==================================================  =====================
``.csv``    wide CSV (VHDC horse layout), see :mod:`.read_csv`  mm unless ``# units:``
``.trc``    OpenSim TRC, see :mod:`.read_trc`                   ``Units`` header
``.c3d``    C3D (pure-Python ``c3d`` package), :mod:`.read_c3d`  ``POINT:UNITS``
``.npz``    NumPy archive, see :mod:`.read_npz`                 ``units`` key, else m
``.mat``    MATLAB v5 or v7.3, QTM export, :mod:`.read_mat`      mm (QTM)
==========  ==================================================  =====================

Every reader returns positions in metres with missing samples (blank fields, NaN, C3D
residual -1) masked, and raises :class:`activebonds.errors.InputError` (one line naming
the file and the line or field) for anything it cannot read.  ``rate`` is only needed for
files without a rate of their own (a CSV without time column); when the file has one,
a disagreement of more than 1 % is an error.  ``units`` overrides the file's units.

An interrupted export leaves a CSV or TRC file with an incomplete last row: it is dropped
with a :class:`TruncatedRowWarning` (one line: file, line number, what is missing), and
``strict=True`` refuses the file instead (see :func:`._table.incomplete_last_row`).  Binary
formats are read whole or refused.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from activebonds.data._common import TruncatedRowWarning, by_extension
from activebonds.data.read_c3d import read_c3d
from activebonds.data.read_csv import read_csv
from activebonds.data.read_mat import read_mat
from activebonds.data.read_npz import read_npz
from activebonds.data.read_trc import read_trc
from activebonds.data.trajectory import Trajectory
from activebonds.errors import InputError  # what read_trajectory raises, for its callers

READERS: dict[str, Callable[..., Trajectory]] = {
    ".csv": read_csv,
    ".trc": read_trc,
    ".c3d": read_c3d,
    ".npz": read_npz,
    ".mat": read_mat,
}
#: The readers that take ``strict`` (the others read a file whole or refuse it).
_STRICT_READERS = (read_csv, read_trc, read_mat)

__all__ = ["READERS", "InputError", "TruncatedRowWarning", "read_trajectory"]


def read_trajectory(
    path: str | Path, rate: float | None = None, units: str | None = None, strict: bool = False
) -> Trajectory:
    """Read a trajectory file (.csv, .trc, .c3d, .npz, .mat) into a :class:`Trajectory` in metres.

    Args:
        path: the file; its extension selects the format.
        rate: sample rate in Hz, required only when the file has none (CSV without a time
            column); otherwise checked against the file (> 1 % apart is an InputError).
        units: length unit of the numbers in the file ("mm", "cm", "m"), overriding what
            the file says (CSV files default to mm).
        strict: refuse a CSV or TRC file whose last row is incomplete (truncated) instead
            of dropping that row with a :class:`TruncatedRowWarning`.

    Raises:
        InputError: unknown extension, unreadable or malformed file.
    """
    path = Path(path)
    reader = by_extension(READERS, path)
    if reader in _STRICT_READERS:
        return reader(path, rate=rate, units=units, strict=strict)
    return reader(path, rate=rate, units=units)
