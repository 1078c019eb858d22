"""The ``tagloc`` command line: thin typer glue over pure functions that return result objects.

Every :class:`~tagloc.errors.TaglocError` becomes one line on stderr and exit code 1; anything
else is a bug and keeps its traceback. A command that fails (an error, Ctrl-C, SIGTERM or SIGHUP)
leaves no output it created (:func:`tagloc.fileutil.removing_created_outputs`); a termination
signal exits with ``128 + signal``. Heavy modules are imported inside the commands so
``tagloc --help`` stays fast.
"""

from __future__ import annotations

import inspect
import os
import signal
import sys
from types import FrameType

import typer
import typer.rich_utils

from tagloc.cli.app import app
from tagloc.errors import TaglocError
from tagloc.fileutil import removing_created_outputs


def _terminated(signum: int, frame: FrameType | None) -> None:
    """A termination signal unwinds the command like an error (outputs removed on the way)."""
    signal.signal(signum, signal.SIG_DFL)  # a second signal ends the process at once
    print(f"tagloc: error: terminated by {signal.Signals(signum).name}", file=sys.stderr)
    raise SystemExit(128 + signum)

#: Width of the help when the output is not a terminal (a pipe, a file, ``less``) and neither
#: ``COLUMNS`` nor ``TERMINAL_WIDTH`` says otherwise: rich would use 80.
HELP_WIDTH = 120


def main() -> None:
    """Entry point of the ``tagloc`` console script."""
    if (
        typer.rich_utils.MAX_WIDTH is None
        and not sys.stdout.isatty()
        and "COLUMNS" not in os.environ
    ):
        typer.rich_utils.MAX_WIDTH = HELP_WIDTH
    command = typer.main.get_command(app)
    unwrap_help(command)
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, _terminated)
    try:
        with removing_created_outputs():
            command(prog_name="tagloc")
    except TaglocError as exc:
        print(f"tagloc: error: {exc}", file=sys.stderr)
        sys.exit(1)


def unwrap_help(command: object) -> None:
    """Join the lines of the first paragraph of every command's help, recursively.

    Docstrings wrap at 100 columns; rich keeps those line breaks in a group's list of commands,
    which breaks sentences mid-way at any other width. The first paragraph is one sentence or
    two, so it is made one line and rich wraps it to the terminal.
    """
    help_text = getattr(command, "help", None)
    if isinstance(help_text, str):
        first, sep, rest = inspect.cleandoc(help_text).partition("\n\n")
        command.help = " ".join(first.split()) + sep + rest  # type: ignore[attr-defined]
    for sub in getattr(command, "commands", {}).values():
        unwrap_help(sub)
