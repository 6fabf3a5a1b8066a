"""Creating a run directory and the space it takes (private to :class:`~.RunDir`): the checks
of a new run's folder, the atomic creation, the estimate of what a run writes and the refusal
of a folder without that much free space."""

from __future__ import annotations

import json
import shutil
import threading
from pathlib import Path

import numpy as np

from ... import atomic
from ...atomic import staged_directory
from ...errors import InputError
from ._files import RunWriteError

# Held while this process creates a run directory or probes the folder it goes in: the
# command line's interrupt handler (cli/interrupts.py) waits for it, so an interrupt never
# leaves a half-made run or a probe file behind.
CREATING = threading.Lock()
SMALL_FILES = 256 * 1024  # run.json, status, best model, refinement, uncertainty: at most


def _safe_run_path(out: str | Path) -> Path:
    out = atomic.output_path(out)
    if out.name in ("", ".", "/"):
        raise InputError(out, "give a new folder name for the run")
    return out


def check_new(out: str | Path, overwrite: bool) -> Path:
    """Refuse (:class:`InputError`) a run directory path that :func:`create` would refuse:
    an existing run without ``overwrite``, anything else that exists, a parent folder
    that does not exist or is a file."""
    out = _safe_run_path(out)
    if out.exists() and not overwrite:
        raise InputError(out, "already exists; choose another --out or pass --overwrite")
    if out.exists() and not (out.is_dir() and (out / "run.json").is_file()):
        raise InputError(out, "exists and is not a run directory; --overwrite only replaces runs")
    parent = out.absolute().parent
    for above in (parent, *parent.parents):
        if above.exists() and not above.is_dir():
            raise InputError(out, f"{above} is a file, not a folder")
    if not parent.is_dir():
        raise InputError(out, f"the parent folder {parent} does not exist")
    return out


def create(
    out: str | Path, files: dict[str, bytes], meta: dict, overwrite: bool, need_bytes: int = 0
) -> Path:
    """Create RUN/ atomically: everything is written into a hidden sibling first, then renamed.
    An existing run is never replaced unless ``overwrite``. With ``need_bytes`` (what the run
    will write besides ``files``), a folder with less free space is refused up front."""
    out = check_new(out, overwrite)
    need = need_bytes + sum(len(data) for data in files.values())
    check_space(out, out.absolute().parent, need, "the run writes")
    try:
        with CREATING, staged_directory(out) as tmp:
            (tmp / "checkpoints").mkdir()
            for name, data in files.items():
                (tmp / name).write_bytes(data)
            (tmp / "run.json").write_text(json.dumps(meta, indent=2, sort_keys=True) + "\n")
    except OSError as err:
        raise RunWriteError(out, err) from err
    return out


def expected_bytes(state_bytes: int, columns: int, generations: int) -> int:
    """What a run writes besides the copies of its inputs, estimated from above: its
    checkpoints (two kept, a third being written: the loop state of ``state_bytes`` and the
    history, ``columns`` numbers per generation), history.csv and the small files."""
    history = generations * columns * 8
    return 3 * (state_bytes + history + 4096) + generations * columns * 25 + SMALL_FILES


def state_bytes(shapes: dict[str, tuple]) -> int:
    """Bytes of a checkpointed state of these shapes (``RunDir.state_shapes``), 8 per number."""
    return sum(8 * int(np.prod(shape)) for shape in shapes.values())


def check_space(run: Path, folder: Path, need: int, what: str) -> None:
    """One line (:class:`InputError`) if ``folder`` has less than ``need`` bytes free."""
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return  # unknown: the writes themselves will tell
    if free < need:
        raise InputError(
            run,
            f"not enough free space: {what} about {_megabytes(need)} and {folder} has "
            f"{_megabytes(free)} free; free some space or choose another folder",
        )


def _megabytes(n: int) -> str:
    return f"{n / 1e6:.2g} MB" if n < 1e7 else f"{n / 1e6:.0f} MB"
