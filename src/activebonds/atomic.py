"""Atomic file writes: a temporary file in the same folder, flushed to disk, then renamed, so a
reader (or a resumed run) never sees a half-written file."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

TMP_PREFIX = ".tmp-"


def output_path(path: str | Path) -> Path:
    """An output path with its ``..`` resolved as the system would follow it (symbolic links
    before a ``..`` included), so that its name and its folder are the real ones: ``sub/../x``
    is ``x`` in the current folder, ``a/..`` is the current folder itself (whose name, not
    ``..``, every later check sees: an existing folder is never mistaken for a new one). A
    path without ``..`` is returned as given (its messages keep the user's spelling)."""
    path = Path(path)
    if ".." not in path.parts:
        return path
    if path.name in ("", ".", ".."):
        return path.resolve()
    return path.parent.resolve() / path.name


def write_atomic(path: str | Path, write: Callable[[IO[bytes]], None]) -> Path:
    """Write through ``write(fh)`` into a temporary sibling, fsync, then rename over ``path``
    (keeping the mode of a file it replaces). On any error the target is left untouched."""
    path = Path(path)
    try:
        mode = path.stat().st_mode & 0o777
    except OSError:
        mode = 0o666 & ~_umask()
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f"{TMP_PREFIX}{path.name}.")
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text_atomic(path: str | Path, text: str) -> Path:
    return write_atomic(path, lambda fh: fh.write(text.encode("utf-8")))


def remove_leftovers(folder: str | Path) -> int:
    """Delete temporary files left by an interrupted atomic write; returns how many."""
    n = 0
    for p in Path(folder).glob(f"{TMP_PREFIX}*"):
        p.unlink(missing_ok=True)
        n += 1
    return n


def staged_prefix(target: str | Path) -> str:
    """The name with which :func:`staged_directory`'s folders for ``target`` begin."""
    return f".{Path(target).name}.partial-"


@contextmanager
def staged_directory(target: str | Path) -> Iterator[Path]:
    """Yield a new empty folder beside ``target`` (its parent must exist); on success it
    replaces ``target`` in one rename, on error it is removed and ``target`` is left as it
    was. Callers decide beforehand whether ``target`` may be replaced."""
    target = Path(target)
    parent = target.absolute().parent
    tmp = Path(tempfile.mkdtemp(dir=parent, prefix=staged_prefix(target)))
    try:
        os.chmod(tmp, 0o777 & ~_umask())
        yield tmp
        if target.exists():
            trash = Path(tempfile.mkdtemp(dir=parent, prefix=f".{target.name}.old-"))
            os.replace(target, trash / "old")
            os.replace(tmp, target)
            shutil.rmtree(trash, ignore_errors=True)
        else:
            os.replace(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
