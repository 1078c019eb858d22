"""The ``tagloc`` command line: thin typer glue over pure functions that return result objects.

Every :class:`~tagloc.errors.TaglocError` becomes one line on stderr and exit code 1; anything
else is a bug and keeps its traceback. A command that fails (an error, Ctrl-C, SIGTERM or SIGHUP)
leaves no output it created (:func:`tagloc.fileutil.removing_created_outputs`); a termination
signal exits with ``128 + signal``. Heavy modules are imported inside the commands so
``tagloc --help`` stays fast.
"""

from __future__ import annotations

import signal
import sys
from types import FrameType

from tagloc.cli.app import app
from tagloc.errors import TaglocError
from tagloc.fileutil import removing_created_outputs


def _terminated(signum: int, frame: FrameType | None) -> None:
    """A termination signal unwinds the command like an error (outputs removed on the way)."""
    signal.signal(signum, signal.SIG_DFL)  # a second signal ends the process at once
    print(f"tagloc: error: terminated by {signal.Signals(signum).name}", file=sys.stderr)
    raise SystemExit(128 + signum)


def main() -> None:
    """Entry point of the ``tagloc`` console script."""
    for signum in (signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, _terminated)
    try:
        with removing_created_outputs():
            app()
    except TaglocError as exc:
        print(f"tagloc: error: {exc}", file=sys.stderr)
        sys.exit(1)
