"""Ctrl-C in ``fit`` and ``resume``: at any moment, a clean end and a true message.

Python's default, a ``KeyboardInterrupt`` raised wherever the main thread happens to be, does
not work with JAX: raised inside JAX's garbage-collection callback it is printed as "Exception
ignored" and lost, so the fit goes on (jax-ml/jax#18246); raised while a module imports, it
becomes an ImportError with a traceback; and an interpreter that tears down after one, with
XLA's threads alive, crashed with a segmentation fault (3 of 20 interrupted fits here). So the
command line's process (only it: :func:`install` does nothing in a process that merely imports
this package) handles SIGINT itself:

* Python's handler for SIGINT does nothing; the signal's byte arrives, through
  ``signal.set_wakeup_fd``, on a pipe read by a watcher thread, at once, even while the main
  thread compiles in native code.
* Before the run directory exists ("start-up"): the process ends at once, exit 130,
  "interrupted before the run started; nothing was written". The watcher decides while it holds
  ``rundir.CREATING``, the lock under which a run directory is created (and its folder probed),
  so the claim is true: no run, no hidden partial folder.
* Once the run exists: the first Ctrl-C is recorded and said ("stopping at the end of this
  step"); the main thread acts on it at its next safe point: after each chunk of generations
  (:func:`check`), where the driver writes a checkpoint, and between two Levenberg-Marquardt
  steps of the refinement (polled through :func:`activebonds.runtime.stop_requested`), where
  the refinement saves its finished stages and the one under way; then "interrupted;
  continue with: activebonds resume RUN", exit 130 (``resume`` continues the refinement from
  there). A second Ctrl-C ends the process at once with the same advice: a run killed at any
  moment resumes to the uninterrupted result (docs/RELIABILITY.md section 1).
* After the fit has returned, its results saved (while its summary is printed), or if Ctrl-C
  was pressed in its last phases after the refinement (baselines, uncertainty, which have no
  safe point): the process ends at once, "interrupted after the fit completed; its results
  are in RUN".

Every end on an interrupt leaves through :func:`exit_now`: output flushed, then ``os._exit``,
never the interpreter's teardown.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from pathlib import Path

EXIT_CODE = 130  # 128 + SIGINT, the shell's convention
COMMANDS = ("fit", "resume")

_guard: _Guard | None = None


class _Guard:
    def __init__(self, command: str):
        self.command = command
        self.phase = "start-up"  # -> "run" (the run directory exists) -> "done"
        self.out: Path | None = None  # fit --out, once known
        self.before: tuple | None = None  # its identity before the fit (with --overwrite)
        self.pending = False  # a Ctrl-C the main thread is to act on
        self.outcome = ""  # the fit's status, once it returned
        self.lock = threading.Lock()  # phase changes against the watcher's decisions
        self.read_fd, self.write_fd = os.pipe()
        os.set_blocking(self.write_fd, False)

    # ----------------------------------------------------------------- the watcher thread
    def watch(self) -> None:
        while True:
            try:
                data = os.read(self.read_fd, 64)
            except OSError:
                return
            if not data:
                return
            for number in data:
                if number == signal.SIGINT:
                    self.interrupted()

    def interrupted(self) -> None:
        creating = _creating_lock()
        if creating is not None:
            creating.acquire()  # a run directory is never left half-made
        try:
            with self.lock:
                if self.phase == "start-up" and self.run_exists():
                    self.phase = "run"
                if self.phase == "start-up":
                    started = "resumed" if self.command == "resume" else "started"
                    exit_now(f"interrupted before the run {started}; nothing was written")
                if self.phase == "done":
                    exit_now(self.done_message())
                if self.pending:  # the second Ctrl-C: at once (resumable like a kill -9)
                    exit_now(resume_advice(self.out))
                self.pending = True
        finally:
            if creating is not None:
                creating.release()
        _say("interrupt: stopping at the end of this step (Ctrl-C again stops at once)")

    def done_message(self) -> str:
        if self.outcome == "completed":
            return f"interrupted after the fit completed; its results are in {self.out}"
        return f"interrupted after the fit ended ({self.outcome}); see {self.out}"

    def run_exists(self) -> bool:
        if self.out is None:
            return False
        return _identity(self.out) not in (None, self.before)


def _creating_lock():
    """``rundir.CREATING`` if that module is loaded (it is not imported from this thread: the
    main thread may hold the import lock); without it no run directory can be in creation."""
    rundir = sys.modules.get("activebonds.identify.rundir")
    return getattr(rundir, "CREATING", None)


def _identity(path: Path) -> tuple | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino)


# ----------------------------------------------------------------------------- the main thread
def command_of(argv: list[str]) -> str | None:
    """The command of an ``activebonds`` command line (its first argument not an option)."""
    for arg in argv[1:]:
        if not arg.startswith("-"):
            return arg
    return None


def is_command_line() -> bool:
    """Whether this process is ``activebonds ...`` (the console script) or
    ``python -m activebonds.cli ...``, not a program that imports the package."""
    first = Path(sys.argv[0]) if sys.argv and sys.argv[0] else Path()
    return first.name == "activebonds" or first.parts[-3:] == ("activebonds", "cli", "__main__.py")


def install() -> bool:
    """Take over SIGINT for ``fit`` and ``resume`` in the command line's own process (a no-op
    elsewhere, and when called again). Must run in the main thread, as early as possible."""
    global _guard
    if _guard is not None:
        return True
    command = command_of(sys.argv)
    if command not in COMMANDS or not is_command_line():
        return False
    if threading.current_thread() is not threading.main_thread():
        return False
    try:
        guard = _Guard(command)
        signal.set_wakeup_fd(guard.write_fd, warn_on_full_buffer=False)
        signal.signal(signal.SIGINT, _ignore)
    except (ValueError, OSError, AttributeError):  # not the main interpreter; no such pipe
        return False
    _guard = guard
    from .. import runtime

    runtime.on_stop_request(_pending)  # the refinement's steps poll it (a safe point each)
    threading.Thread(target=guard.watch, name="activebonds-sigint", daemon=True).start()
    return True


def _pending() -> bool:
    """Whether a Ctrl-C waits for the main thread to act on it."""
    return _guard is not None and _guard.pending


def _ignore(signum, frame) -> None:
    """Python's handler for SIGINT: nothing (the watcher thread has the signal's byte)."""


def expect_run(out: Path) -> None:
    """``fit`` will create the run directory ``out``: before it exists, Ctrl-C ends at once."""
    if _guard is not None:
        with _guard.lock:
            _guard.out, _guard.before = Path(out), _identity(Path(out))


def resuming(run: Path) -> None:
    """``resume`` starts working on ``run`` (from now on, interrupts are acted on at safe
    points; before, Ctrl-C ends at once)."""
    if _guard is not None:
        with _guard.lock:
            _guard.out, _guard.phase = Path(run), "run"


def fit_returned(outcome: str) -> None:
    """The fit has returned with status ``outcome``, everything saved: an interrupt pressed
    during its last phases (baselines, uncertainty: no safe point there) ends the command now,
    without the summary; from here on Ctrl-C ends at once."""
    if _guard is None:
        return
    with _guard.lock:
        _guard.phase, _guard.outcome = "done", outcome
        pending = _guard.pending
    if pending:
        exit_now(_guard.done_message())


def check() -> None:
    """A safe point of the main thread: raise KeyboardInterrupt if Ctrl-C was pressed."""
    if _guard is not None and _guard.pending:
        raise KeyboardInterrupt


def active() -> bool:
    return _guard is not None


def resume_advice(run: Path | None) -> str:
    return f"interrupted; continue with: activebonds resume {run}"


def stop(message: str) -> None:
    """End an interrupted command: ``error: MESSAGE``, exit 130 (at once, without the
    interpreter's teardown, in the command line's process; else through typer)."""
    if _guard is not None:
        exit_now(message)
    from .app import fail

    fail(message, code=EXIT_CODE)


def exit_now(message: str, code: int = EXIT_CODE) -> None:
    """Flush what was printed, print ``error: MESSAGE`` and end the process with ``code``
    without running the interpreter's teardown (any thread may call it)."""
    _flush_within(1.0)
    text = f"error: {message}\n"
    if _isatty(2):
        text = "\x1b[?25h\n" + text  # the cursor a live display hid; off the progress line
    try:
        os.write(2, text.encode("utf-8", "replace"))
    finally:
        os._exit(code)


def _say(line: str) -> None:
    """A line on stderr from the watcher thread (through sys.stderr, so that a live progress
    display prints it above itself)."""
    done = threading.Event()

    def write():
        try:
            sys.stderr.write(line + "\n")
            sys.stderr.flush()
        except Exception:  # noqa: BLE001 - a closed or odd stderr: say nothing
            pass
        done.set()

    threading.Thread(target=write, daemon=True).start()
    done.wait(1.0)


def _flush_within(seconds: float) -> None:
    """Flush stdout and stderr, giving up after ``seconds`` (a stream another thread holds
    must not keep the process from ending)."""
    done = threading.Event()

    def flush():
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except Exception:  # noqa: BLE001 - a closed stream: nothing to flush
                pass
        done.set()

    threading.Thread(target=flush, daemon=True).start()
    done.wait(seconds)


def _isatty(fd: int) -> bool:
    try:
        return os.isatty(fd)
    except OSError:
        return False
