"""Atomic output for reports: a figures folder built aside and swapped in whole, and the HTML
file written to a temporary file then renamed."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .. import atomic
from ..atomic import write_text_atomic
from ..errors import InputError

FIGURE_SUFFIXES = {".png", ".svg", ".gif", ".mp4", ".json"}


def check_replaceable(target: Path) -> None:
    """Refuse (InputError) to replace anything but a folder of figures."""
    if not target.exists():
        return
    if not target.is_dir() or target.is_symlink():
        raise InputError(target, "exists and is not a figures folder; move it away first")
    foreign = [p.name for p in target.iterdir() if p.suffix.lower() not in FIGURE_SUFFIXES]
    if foreign:
        raise InputError(
            target,
            f"holds files that are not figures ({', '.join(sorted(foreign)[:3])}); "
            "not replacing it",
        )


@contextmanager
def staged_directory(target: str | Path) -> Iterator[Path]:
    """Yield a new empty folder beside ``target``; on success it replaces ``target`` (which
    may only hold figures), on error it is removed and ``target`` is left as it was."""
    target = Path(target)
    parent = target.absolute().parent
    if not parent.is_dir():
        raise InputError(target, f"the folder {parent} does not exist")
    check_replaceable(target)
    with atomic.staged_directory(target) as tmp:
        yield tmp


def write_html(path: str | Path, text: str) -> Path:
    """Write the HTML atomically (temporary file in the same folder, then rename)."""
    path = Path(path)
    if not path.absolute().parent.is_dir():
        raise InputError(path, "the folder does not exist")
    return write_text_atomic(path, text)
