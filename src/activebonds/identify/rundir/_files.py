"""The run directory's writes and hashes (private to :class:`~.RunDir`): every write atomic,
a failure a :class:`RunWriteError` naming the file."""

from __future__ import annotations

import hashlib
from pathlib import Path

from ... import atomic


class RunWriteError(OSError):
    """A file of a run directory could not be written (a full disk, a lost permission): the
    OSError of the write, with the file's path. The atomic writes leave the file they were to
    replace, and every older checkpoint, as they were."""

    def __init__(self, path: str | Path, error: OSError):
        super().__init__(error.errno, error.strerror or str(error), str(path))
        self.path, self.error = Path(path), error


def write_atomic(path: str | Path, write) -> Path:
    """:func:`activebonds.atomic.write_atomic`; a failure is a :class:`RunWriteError`."""
    try:
        return atomic.write_atomic(path, write)
    except OSError as err:
        raise RunWriteError(path, err) from err


def write_text_atomic(path: str | Path, text: str) -> Path:
    return write_atomic(path, lambda fh: fh.write(text.encode("utf-8")))


def sha256_file(path: str | Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
