"""The command-line application object and its one-line error printer, shared by every
command module (the modules register their commands on it; :mod:`.main` imports them all)."""

from __future__ import annotations

import sys
import warnings

import typer
from rich.console import Console

from ..errors import InputError

app = typer.Typer(
    help="Identify active particle-bond models (springs, dampers, mechanical-neural bonds) "
    "from motion capture with a self-adaptive evolution strategy.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)
# Not a terminal (a log, a pipe): no 80-column wrapping of paths and summaries.
out = Console() if sys.stdout.isatty() else Console(width=160, soft_wrap=True)
err = Console(stderr=True, width=10_000, soft_wrap=True)


def fail(error: InputError | str, code: int = 2):
    text = error.line() if isinstance(error, InputError) else str(error)
    err.print(f"error: {text}", markup=False, highlight=False, soft_wrap=True)
    raise typer.Exit(code)


def parse_option_frames(text, parse):
    try:
        return parse(text)
    except ValueError as e:
        raise InputError("--frames", str(e)) from None


_python_showwarning = warnings.showwarning
_warned: set[str] = set()


def show_warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` of the command line: a reader's warning about the user's
    file (a truncated last row) prints as one line on stderr, ``warning: FILE: line N:
    ...``, once per message; any other warning prints as Python prints it."""
    from ..data.readers import TruncatedRowWarning

    if not issubclass(category, TruncatedRowWarning):
        _python_showwarning(message, category, filename, lineno, file, line)
        return
    text = " ".join(str(message).split())
    if text not in _warned:
        _warned.add(text)
        err.print(f"warning: {text}", markup=False, highlight=False, soft_wrap=True)


def one_line_warnings() -> None:
    """Install :func:`show_warning_line` (called by ``main()``)."""
    warnings.showwarning = show_warning_line
