"""Atomic file output: write to a temporary file beside the target, then rename over it.

A crash or an error half-way through never leaves a truncated output where a previous good one
was. A directory at the target is never replaced.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path

from tagloc.errors import TaglocError

__all__ = ["AtomicTextStream", "OutputPathError", "atomic_path", "atomic_write_text",
           "atomic_write_texts"]  # fmt: skip

#: Characters a temporary name adds to its target's name and suffix (``.``, ``.``, 8, ``.tmp``).
TEMP_EXTRA = 14


class OutputPathError(TaglocError, ValueError):
    """An output path that cannot be written; the message names the option and the path."""


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path in the target's directory; rename it to ``path`` on success.

    The temporary file keeps the target's suffix (so writers that infer the format from it, like
    matplotlib's ``savefig``, still work). On an exception the temporary file is removed and the
    target is left untouched. Missing parent directories are created.

    Raises
    ------
    OutputPathError
        If ``path`` is an existing directory (it is never replaced, nor removed).
    """
    target = Path(path)
    if target.is_dir():
        raise OutputPathError(f"{target}: is a directory; give a file name")
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(
        dir=target.parent, prefix=f".{target.name}.", suffix=f".tmp{target.suffix}"
    )
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        if tmp.exists():  # mkstemp creates 0600: give the output the permissions of a new file
            os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


class AtomicTextStream:
    """A text file written line by line into a temporary file beside ``path``: :meth:`commit`
    renames it to ``path``, :meth:`abort` removes it (``path`` keeps what it held before)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self._ctx = atomic_path(self.path)
        self._tmp = self._ctx.__enter__()
        self._handle = open(self._tmp, "w", encoding="utf-8")  # noqa: SIM115 (closed below)

    def write(self, text: str) -> None:
        self._handle.write(text)

    def commit(self) -> Path:
        """Close and rename into place; return the path."""
        self._handle.close()
        self._ctx.__exit__(None, None, None)
        return self.path

    def abort(self) -> None:
        """Close and discard."""
        self._handle.close()
        self._ctx.__exit__(_AbortedError, _AbortedError(), None)  # the temporary file is removed


class _AbortedError(Exception):
    pass


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def atomic_write_texts(files: Mapping[Path, str]) -> None:
    """Write several text files (UTF-8) so that a failure leaves none of them changed.

    Every text is written to its temporary file first; only when all are written are they
    renamed into place (a rename failing half-way is the one case that leaves some renamed).
    """
    with contextlib.ExitStack() as stack:
        for path, text in files.items():
            stack.enter_context(atomic_path(path)).write_text(text, encoding="utf-8")
