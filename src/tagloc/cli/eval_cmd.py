"""``tagloc eval``: evaluation commands (each a few lines around a pure function).

Sub-commands register themselves on :data:`eval_app` from their own modules.
"""

from __future__ import annotations

import typer

eval_app = typer.Typer(
    help="Evaluate: localization runs against ground truth, the tag sensor by sweep.",
    no_args_is_help=True,
)
