"""The ``tagloc`` command line: thin typer glue over pure functions that return result objects.

Every :class:`~tagloc.errors.TaglocError` becomes one line on stderr and exit code 1; anything
else is a bug and keeps its traceback. Heavy modules are imported inside the commands so
``tagloc --help`` stays fast.
"""

from __future__ import annotations

import sys

from tagloc.cli.app import app
from tagloc.errors import TaglocError


def main() -> None:
    """Entry point of the ``tagloc`` console script."""
    try:
        app()
    except TaglocError as exc:
        print(f"tagloc: error: {exc}", file=sys.stderr)
        sys.exit(1)
