"""Atomic file output (:mod:`tagloc.fileutil.atomic`: :func:`atomic_path`,
:func:`atomic_write_text`, ...), and the check of a command's output paths before any work
starts, with the clean-up of what a failed command created (:mod:`tagloc.fileutil.outputs`:
:func:`check_outputs`, :func:`removing_created_outputs`).
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
