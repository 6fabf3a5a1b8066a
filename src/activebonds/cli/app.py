"""The command-line application object and its one-line error printer, shared by every
command module (the modules register their commands on it; :mod:`.main` imports them all).

Nothing here or in the command modules imports JAX or the numerics at module level: help,
``--version`` and a bad option answer at once (``benchmarks/cli_startup.py``); each command
imports what it computes with, and :func:`command_line` runs the process's JAX settings only
once a command's arguments are parsed.
"""

from __future__ import annotations

import functools
import sys
import warnings
from collections.abc import Callable
from typing import Annotated

import typer
from rich.console import Console

from ..errors import InputError

app = typer.Typer(
    help="Identify active particle-bond models (springs, dampers, mechanical-neural bonds) "
    "from motion capture with a self-adaptive evolution strategy.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # plain help: wrapped, never cut with "…" at 80 columns
    add_completion=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def console(**options) -> Console:
    """A console that prints text as given: the terminal library's markup (``[bold]``), emoji
    codes (``:100:``) and highlighting are never applied, so file names, marker names and
    ranges such as ``0:100:`` print verbatim (tables included)."""
    return Console(markup=False, emoji=False, highlight=False, **options)


# Not a terminal (a log, a pipe): no 80-column wrapping of paths and summaries.
out = console() if sys.stdout.isatty() else console(width=160, soft_wrap=True)
err = console(stderr=True, width=10_000, soft_wrap=True)


def say(line: str) -> None:
    """One line of plain text on stdout (no markup: names and ranges printed verbatim)."""
    out.print(line, markup=False, highlight=False, emoji=False)


def fail(error: InputError | str, code: int = 2):
    text = error.line() if isinstance(error, InputError) else str(error)
    err.print(f"error: {text}", markup=False, highlight=False, soft_wrap=True)
    raise typer.Exit(code)


def parse_option_frames(text, parse, option: str = "--frames"):
    """START:STOP of ``option`` through ``parse``, or one line naming the option."""
    try:
        return parse(text)
    except ValueError as e:
        raise InputError(option, str(e)) from None


_python_showwarning = warnings.showwarning
_warned: set[str] = set()


def show_warning_line(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` of the command line: a reader's warning about the user's
    file (a truncated last row, units in doubt) prints as one line on stderr, ``warning: FILE: line N:
    ...``, once per message; any other warning prints as Python prints it."""
    from ..data._common import FileWarning

    if not issubclass(category, FileWarning):
        _python_showwarning(message, category, filename, lineno, file, line)
        return
    text = " ".join(str(message).split())
    if text not in _warned:
        _warned.add(text)
        err.print(f"warning: {text}", markup=False, highlight=False, soft_wrap=True)


def one_line_warnings() -> None:
    """Install :func:`show_warning_line` (called by ``main()``)."""
    warnings.showwarning = show_warning_line


def _print_version(value: bool) -> None:
    if not value:
        return
    from importlib import metadata

    try:
        version = metadata.version("activebonds")
    except metadata.PackageNotFoundError:  # run from a source tree that was never installed
        from .. import __version__ as version
    print(f"activebonds {version}")
    raise typer.Exit(0)


@app.callback()
def _options(
    version: Annotated[
        bool,
        typer.Option(
            "--version",
            help="Print the version and exit.",
            is_eager=True,
            callback=_print_version,
        ),
    ] = False,
) -> None:
    pass


def command_line(setup: Callable[[], None]):
    """The click command of :data:`app` with ``setup()`` run at the start of every command,
    after its arguments are parsed: ``--help``, ``--version`` and a usage error never run it
    (``main()`` passes the JAX settings, :func:`activebonds.runtime.compilation_cache`,
    which import JAX)."""
    from typer.main import get_command

    group = get_command(app)
    for command in group.commands.values():
        command.callback = _after(setup, command.callback)
        command.short_help = command.short_help or first_sentence(command.help or "")
    return group


def first_sentence(text: str) -> str:
    """A command's help up to its first full stop: its line in ``activebonds --help``, whole
    (the parser's own short help is cut with '...' at the terminal's width)."""
    words = " ".join(text.split())
    end = words.find(". ")
    return words if end < 0 else words[: end + 1]


def _after(setup: Callable[[], None], body: Callable) -> Callable:
    @functools.wraps(body)
    def run(*args, **kwargs):
        setup()
        return body(*args, **kwargs)

    return run
