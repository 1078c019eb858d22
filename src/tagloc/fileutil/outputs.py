"""The check of a command's output paths before any work starts, and the clean-up if it fails.

- :func:`check_outputs`: every output path of a command, checked at once before it reads or
  computes anything, so a bad path fails in one line instead of after minutes of work (and leaves
  nothing behind).
- :func:`removing_created_outputs`: around a command, removes again what the command created
  where :func:`check_outputs` found nothing (its output directory, missing parents, its files)
  if the command fails, also on Ctrl-C or a termination signal turned into ``SystemExit``; an
  output directory that existed is left as it was (atomic writes never touched its files).
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Callable, Collection, Iterator, Mapping
from pathlib import Path

from tagloc.fileutil.atomic import TEMP_EXTRA, OutputPathError

PathArg = str | os.PathLike[str]


#: Per active :func:`removing_created_outputs`: the paths check_outputs found missing.
_GUARDS: list[list[Path]] = []


@contextlib.contextmanager
def removing_created_outputs() -> Iterator[None]:
    """Remove, if the block fails, every output path :func:`check_outputs` found missing in it.

    A failure is any exception but ``SystemExit`` with code 0 (``sys.exit(0)`` of a command that
    succeeded). Each path removed is the topmost of an output's missing ancestors (a directory
    removed with what the command put in it) or a missing output file; nothing that existed when
    :func:`check_outputs` looked is touched.
    """
    missing: list[Path] = []
    _GUARDS.append(missing)
    try:
        yield
    except BaseException as exc:
        if not (isinstance(exc, SystemExit) and exc.code in (0, None)):
            for path in reversed(missing):
                if path.is_dir() and not path.is_symlink():
                    shutil.rmtree(path, ignore_errors=True)
                elif path.is_file() or path.is_symlink():
                    path.unlink(missing_ok=True)
        raise
    finally:
        _GUARDS.remove(missing)


def _note_missing(path: Path) -> None:
    """Record the topmost missing one of ``path`` and its ancestors with the active guard."""
    if not _GUARDS or path.exists() or path.is_symlink():
        return
    while not path.parent.exists() and path.parent != path:
        path = path.parent
    if path not in _GUARDS[-1]:
        _GUARDS[-1].append(path)


def check_outputs(
    outputs: Mapping[str, PathArg | None],
    *,
    directories: Mapping[str, Collection[str]] | None = None,
    replaceable: Mapping[str, Callable[[Path], bool]] | None = None,
    inputs: Mapping[str, PathArg | None] | None = None,
) -> dict[str, Path]:
    """Check every output path of a command before it starts work; nothing is left behind.

    An output passes if it can be written where it is and takes nothing it must not:

    - its nearest existing ancestor is a directory this process can create files in (tested by
      creating and removing a probe file there, the one test that sees permissions, ACLs and
      read-only mounts alike; missing parent directories are created later, by the writer);
    - its name leaves room for the temporary name beside it (``NAME_MAX``);
    - a file output is not an existing directory (nor a device, FIFO, ...): an existing regular
      file is replaced, an existing directory never is, unless ``replaceable[option](path)``
      says it is one the writer may replace (a ROS 2 bag directory and nothing else);
    - an output directory (an option in ``directories``) is a directory if it exists, and each
      file the command writes into it passes as a file output;
    - no two outputs resolve to the same path (symlinks and ``..`` resolved),
      none lies inside another file or bag output, and none is one of the command's ``inputs``.

    Parameters
    ----------
    outputs : mapping of str to path or None
        Option name (as the user typed it, e.g. ``"--out"``) to output path; None (an output
        that was not asked for) is skipped.
    directories : mapping of str to collection of str, optional
        The options of ``outputs`` that name an output directory, each with the names (relative
        paths) of the files the command writes into it (may be empty).
    replaceable : mapping of str to callable, optional
        Option to a predicate on an existing directory at that output: True if the writer may
        replace it (e.g. :func:`tagloc.io.is_ros2_bag_directory` for ``--format ros2``).
    inputs : mapping of str to path or None, optional
        Option (or argument name) to input path: an output may not overwrite an input.

    Returns
    -------
    dict of str to Path
        The resolved output paths by option (skipped ones left out).

    Raises
    ------
    OutputPathError
        One line, ``"<option> <path>: <reason>"``, for the first output that fails.
    """
    directories = directories or {}
    replaceable = replaceable or {}
    resolved: dict[str, Path] = {}
    claimed: list[_Claim] = []
    for option, raw in outputs.items():
        if raw is None:
            continue
        path = _resolve(option, raw)
        resolved[option] = path
        try:
            if option in directories:
                _check_directory(option, raw, path)
                children = [(name, path / name) for name in directories[option]]
                for name, child in children:
                    _check_file(option, Path(raw) / name, child, None)
                claimed += [(child, option, f"{raw}/{name}", True) for name, child in children]
                claimed.append((path, option, str(raw), False))
            else:
                _check_file(option, raw, path, replaceable.get(option))
                claimed.append((path, option, str(raw), True))
        except OSError as exc:  # a name too long, a loop of links, ... while looking
            reason = exc.strerror or exc.__class__.__name__
            raise OutputPathError(f"{option} {raw}: {reason}") from None
    _check_clashes(claimed)
    for name, raw_input in (inputs or {}).items():
        if raw_input is None:
            continue
        try:
            source = _resolve(name, raw_input)
        except OutputPathError:
            continue  # an input that cannot be resolved cannot be overwritten either
        for path, option, shown, _ in claimed:
            if path == source:
                raise OutputPathError(f"{option} {shown}: is also the input {name} {raw_input}")
    for path, *_ in claimed:  # what a failed command removes again (removing_created_outputs)
        _note_missing(path)
    return resolved


#: An output path: resolved, its option, as the user wrote it, written as one unit (not a directory
#: the command fills).
_Claim = tuple[Path, str, str, bool]


def _resolve(option: str, raw: PathArg) -> Path:
    if not os.fspath(raw):
        raise OutputPathError(f"{option}: empty path")
    try:
        return Path(raw).expanduser().resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop
        raise OutputPathError(f"{option} {raw}: cannot resolve the path ({exc})") from None


def _check_file(
    option: str, raw: PathArg, path: Path, replaceable: Callable[[Path], bool] | None
) -> None:
    if path.is_dir():
        if replaceable is None:
            raise OutputPathError(f"{option} {raw}: is an existing directory; give a file name")
        if not replaceable(path):
            raise OutputPathError(
                f"{option} {raw}: is an existing directory this output may not replace"
            )
    elif path.exists() and not path.is_file():
        raise OutputPathError(f"{option} {raw}: exists and is not a regular file")
    _check_parent(option, raw, path.parent)
    # the temporary file beside it is named ".<name>.<8 random>.tmp<suffix>"
    if len(os.fsencode(path.name + path.suffix)) + TEMP_EXTRA > _name_max(path.parent):
        raise OutputPathError(f"{option} {raw}: file name too long")


def _check_directory(option: str, raw: PathArg, path: Path) -> None:
    if path.exists() and not path.is_dir():
        raise OutputPathError(f"{option} {raw}: exists and is not a directory")
    _check_parent(option, raw, path)


def _name_max(directory: Path) -> int:
    while not directory.exists():
        directory = directory.parent
    try:
        return int(os.pathconf(directory, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return 255


def _check_parent(option: str, raw: PathArg, directory: Path) -> None:
    """The nearest existing ancestor of ``directory`` (itself included) takes new files."""
    existing = directory
    while not existing.exists():
        if len(os.fsencode(existing.name)) > _name_max(existing):
            raise OutputPathError(f"{option} {raw}: directory name too long")
        existing = existing.parent
    if not existing.is_dir():
        raise OutputPathError(f"{option} {raw}: {existing} is not a directory")
    try:  # the only reliable test (permissions, ACLs, read-only mounts, root)
        fd, probe = tempfile.mkstemp(dir=existing, prefix=".tagloc-probe.")
    except OSError as exc:
        reason = exc.strerror or exc.__class__.__name__
        raise OutputPathError(f"{option} {raw}: cannot write in {existing} ({reason})") from None
    os.close(fd)
    os.unlink(probe)


def _check_clashes(claimed: list[_Claim]) -> None:
    """No two options write the same path, nor into an output that is written as one unit."""
    for i, (path, option, shown, whole) in enumerate(claimed):
        for other_path, other, other_shown, other_whole in claimed[:i]:
            if other == option:
                continue
            if path == other_path:
                raise OutputPathError(f"{option} {shown}: the same path as {other} {other_shown}")
            if other_whole and path.is_relative_to(other_path):
                raise OutputPathError(f"{option} {shown}: inside the output {other} {other_shown}")
            if whole and other_path.is_relative_to(path):
                raise OutputPathError(f"{other} {other_shown}: inside the output {option} {shown}")
