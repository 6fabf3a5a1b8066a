"""Where a fit's run directory goes: checked before any computation, and what a write that
fails later says.

* :func:`check_output_folder`: ``fit --out RUN`` must be a new folder (or, with
  ``--overwrite``, a run directory) whose parent exists and takes a file: a probe file is
  created there and removed. A read-only folder, a permission denied, ``--out`` under a file:
  one line, exit 2, before anything is read or compiled. (Free space is checked once the run's
  size is known, before its folder is created: ``RunDir.create``.)
* :func:`write_failure_line`: a write of the run that failed mid-run (a full disk) leaves the
  newest complete checkpoint as it was (the writes are atomic); the line names the file, the
  cause and the checkpoint kept, and how to finish the job.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ..errors import InputError


def check_output_folder(out: Path, overwrite: bool) -> None:
    """Refuse (:class:`InputError`) a run directory ``out`` this process cannot create."""
    from ..identify.rundir import CREATING, RunDir

    out = RunDir.check_new(out, overwrite)
    parent = out.absolute().parent
    with CREATING:  # an interrupt waits: the probe is never left behind
        try:
            fd, probe = tempfile.mkstemp(dir=parent, prefix=f".{out.name}.probe-")
        except OSError as err:
            raise InputError(out, f"cannot write in {parent} ({_cause(err)})") from None
        try:
            os.write(fd, b"probe")
        except OSError as err:
            raise InputError(out, f"cannot write in {parent} ({_cause(err)})") from None
        finally:
            os.close(fd)
            Path(probe).unlink(missing_ok=True)


def write_failure_line(run: Path, err: OSError) -> str:
    """The one line of a run whose write failed: the file, the cause, what is kept, what next."""
    from ..identify.rundir import RunDir

    what = f"could not write {err.filename or run}: {_cause(err)}"
    if err.filename is None or Path(err.filename) == Path(run):  # creating the run folder
        return (
            f"{what}; nothing was kept: free some space (or choose another --out), then fit again"
        )
    gen = RunDir(run).newest_checkpoint()
    if gen is None:
        return (
            f"{what}; no checkpoint was written yet: free some space, then "
            f"`activebonds resume {run}` starts the run again"
        )
    return (
        f"{what}; the checkpoint at generation {gen} is kept: free some space, then "
        f"`activebonds resume {run}`"
    )


def _cause(err: OSError) -> str:
    return err.strerror or str(err)
