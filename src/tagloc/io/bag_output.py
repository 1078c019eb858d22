"""Where a bag may be written: the format a path names, and the one directory a writer may replace.

Policy (:class:`~tagloc.io.BagSink` and ``tagloc sim record``): an MCAP output is a ``.mcap`` file,
a ROS 1 output a ``.bag`` file, a ROS 2 output a directory without either suffix, so that
:class:`~tagloc.io.BagSource` reads back what was written. An existing directory at the target is
never removed, with one exception: a ROS 2 output may replace a directory that holds a ROS 2 bag
and nothing else (``metadata.yaml`` and exactly the storage files it lists, as ``BagSink``
writes it); replacing it loses nothing but the old bag, as overwriting a file would.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from tagloc.io.errors import BagWriteError

BagFormat = Literal["mcap", "ros2", "ros1"]

#: The suffix each file format's output must have.
FORMAT_SUFFIX: dict[str, str] = {"mcap": ".mcap", "ros1": ".bag"}
#: Suffixes a ROS 2 bag directory may not have (they name files the readers open as such).
_FILE_SUFFIXES = (".mcap", ".bag", ".db3", ".bz2")
#: Larger ``metadata.yaml`` files are not a bag tagloc wrote (and are not parsed).
_MAX_METADATA_BYTES = 1 << 20


def bag_output_format(path: str | os.PathLike[str], format: str = "") -> BagFormat:
    """The bag format to write at ``path``: ``format``, or from the suffix if ``format`` is empty.

    Parameters
    ----------
    path : str or PathLike
        The output: ``.mcap`` (MCAP), ``.bag`` (ROS 1), anything else a ROS 2 bag directory.
    format : {"", "mcap", "ros2", "ros1"}
        The format asked for (``--format``); empty to infer it.

    Raises
    ------
    BagWriteError
        One line for an unknown format or a format that does not fit the suffix (a ROS 1 bag
        named ``.mcap``, a ROS 2 directory named ``.bag``, ...).
    """
    suffix = Path(path).suffix.lower()
    if not format:
        return {".mcap": "mcap", ".bag": "ros1"}.get(suffix, "ros2")  # type: ignore[return-value]
    if format not in ("mcap", "ros2", "ros1"):
        raise BagWriteError(f"--format {format!r}: expected mcap, ros2 or ros1")
    if format == "ros2":
        if suffix in _FILE_SUFFIXES:
            raise BagWriteError(
                f"--format ros2 {path}: a ROS 2 bag is a directory; its name may not end in "
                f"{suffix} (use --format {'ros1' if suffix == '.bag' else 'mcap'} or another name)"
            )
        return "ros2"
    if suffix != FORMAT_SUFFIX[format]:
        raise BagWriteError(
            f"--format {format} {path}: {'a ROS 1 bag' if format == 'ros1' else 'an MCAP file'} "
            f"is named *{FORMAT_SUFFIX[format]}" + (f", not *{suffix}" if suffix else "")
        )
    return format  # type: ignore[return-value]


def is_ros2_bag_directory(path: str | os.PathLike[str]) -> bool:
    """True if ``path`` is a directory holding one ROS 2 bag and nothing else.

    That is ``metadata.yaml`` (``rosbag2_bagfile_information.relative_file_paths``) and exactly
    the regular files it lists: the only directory a bag writer may replace.
    """
    import yaml

    root = Path(path)
    meta = root / "metadata.yaml"
    try:
        if root.is_symlink() or not root.is_dir() or meta.stat().st_size > _MAX_METADATA_BYTES:
            return False
        info = yaml.safe_load(meta.read_text(encoding="utf-8"))
        files = info["rosbag2_bagfile_information"]["relative_file_paths"]
        entries = list(root.iterdir())
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError, RecursionError):
        return False
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        return False
    regular = all(e.is_file() and not e.is_symlink() for e in entries)
    return regular and {e.name for e in entries} == {"metadata.yaml", *files}


def check_bag_target(path: Path, format: BagFormat) -> None:
    """Refuse a target the writer may not replace (module docstring); nothing is changed.

    Raises
    ------
    BagWriteError
        An existing directory that is not a lone ROS 2 bag (or any directory for a file
        format), or an existing file where a ROS 2 directory goes.
    """
    if path.is_dir():
        if format != "ros2":
            raise BagWriteError(f"{path}: is an existing directory; give a file name")
        if not is_ros2_bag_directory(path):
            raise BagWriteError(
                f"{path}: is an existing directory that is not a ROS 2 bag; refusing to replace it"
            )
    elif path.exists() and (format == "ros2" or not path.is_file()):
        raise BagWriteError(
            f"{path}: exists and is not a {'directory' if format == 'ros2' else 'file'}"
        )
