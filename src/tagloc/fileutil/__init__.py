"""Atomic file output (:mod:`.atomic`), and the check of a command's output paths before any work
starts (:mod:`.outputs`).

- :func:`atomic_path` / :func:`atomic_write_text`: write to a temporary file beside the target,
  then rename over it. A crash or an error half-way through never leaves a truncated output where
  a previous good one was. A directory at the target is never replaced.
- :func:`check_outputs`: every output path of a command, checked at once before it reads or
  computes anything, so a bad path fails in one line instead of after minutes of work (and leaves
  nothing behind).
- :func:`removing_created_outputs`: around a command, removes again what the command created
  where :func:`check_outputs` found nothing (its output directory, missing parents, its files)
  if the command fails, also on Ctrl-C or a termination signal turned into ``SystemExit``; an
  output directory that existed is left as it was (atomic writes never touched its files).
"""

from tagloc.fileutil.atomic import (
    AtomicTextStream,
    OutputPathError,
    atomic_path,
    atomic_write_text,
    atomic_write_texts,
)
from tagloc.fileutil.outputs import check_outputs, removing_created_outputs

__all__ = [
    "AtomicTextStream", "OutputPathError", "atomic_path", "atomic_write_text",
    "atomic_write_texts", "check_outputs", "removing_created_outputs",
]  # fmt: skip
