"""The path a bag reader opens: the bag itself, or its whole-file ``.bz2`` decompressed once.

``*.bag.bz2`` / ``*.mcap.bz2`` (as the dupont data set ships) are decompressed into a cache
(``<tmp>/tagloc-bags-<uid>/``, keyed by path, size and mtime; the source is never touched),
written atomically and bounded against decompression bombs (:data:`MAX_BZ2_RATIO`).
"""

from __future__ import annotations

import bz2
import hashlib
import logging
import os
import tempfile
from pathlib import Path

from tagloc.fileutil import atomic_path
from tagloc.io.errors import BagFormatError, InputNotFoundError

__all__ = ["BAG_KINDS", "MAX_BZ2_RATIO", "open_bag"]

logger = logging.getLogger(__name__)

#: A ``.bz2`` bag may decompress to at most this many times its size (or 64 MiB), so a small
#: crafted file cannot fill the disk; real bags compress by far less.
MAX_BZ2_RATIO = 200
#: What each bag file extension is, for messages.
BAG_KINDS = {".bag": "a ROS 1 bag", ".mcap": "an MCAP file", ".db3": "a ROS 2 sqlite3 file"}


def open_bag(path: str | os.PathLike[str], cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """The path ``AnyReader`` should open for ``path``, decompressing a ``*.bz2`` file once.

    Parameters
    ----------
    path : str or PathLike
        A ROS 1 ``.bag``, an ``.mcap`` or ``.db3`` file, a ROS 2 bag directory (with
        ``metadata.yaml``), or one of those files compressed whole as ``*.bag.bz2``/``*.mcap.bz2``.
    cache_dir : str or PathLike, optional
        Where decompressed copies live; default ``<tempfile.gettempdir()>/tagloc-bags-<uid>``.

    Returns
    -------
    Path
        ``path`` itself, or the cached decompressed copy (written atomically, reused while the
        source keeps its size and modification time).

    Raises
    ------
    InputNotFoundError
        If ``path`` does not exist.
    BagFormatError
        For an unknown extension, a directory without ``metadata.yaml``, or a corrupt ``.bz2``.
    """
    path = Path(path)
    if not path.exists():
        raise InputNotFoundError(f"{path}: no such bag, MCAP file or ROS 2 bag directory")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise BagFormatError(f"{path}: a directory without metadata.yaml is not a ROS 2 bag")
        return path
    if path.suffix == ".bz2":
        return _decompressed(path, cache_dir)
    if path.suffix not in BAG_KINDS:
        raise BagFormatError(
            f"{path}: unknown bag extension {path.suffix!r} (expected .bag, .mcap, .db3, a "
            "ROS 2 bag directory, or .bag.bz2/.mcap.bz2)"
        )
    return path


def _decompressed(path: Path, cache_dir: str | os.PathLike[str] | None) -> Path:
    inner = Path(path.stem)
    if inner.suffix not in (".bag", ".mcap"):
        raise BagFormatError(f"{path}: expected a compressed .bag or .mcap (name.bag.bz2)")
    stat = path.stat()
    key = f"{path.resolve()}|{stat.st_size}|{stat.st_mtime_ns}"
    user = os.getuid() if hasattr(os, "getuid") else 0  # per user: /tmp is shared
    root = Path(cache_dir) if cache_dir else Path(tempfile.gettempdir()) / f"tagloc-bags-{user}"
    target = root / hashlib.sha256(key.encode()).hexdigest()[:16] / inner.name
    if target.is_file():
        return target
    logger.info("decompressing %s to %s", path, target)
    limit = max(MAX_BZ2_RATIO * stat.st_size, 64 * 2**20)
    try:
        with atomic_path(target) as tmp, bz2.open(path, "rb") as src, tmp.open("wb") as dst:
            written = 0
            while chunk := src.read(1 << 20):
                written += len(chunk)
                if written > limit:
                    raise BagFormatError(
                        f"{path}: decompresses to more than {limit} bytes ({MAX_BZ2_RATIO} times "
                        "its size); refusing it as a decompression bomb"
                    )
                dst.write(chunk)
    except BagFormatError:
        raise
    except (OSError, EOFError, ValueError) as exc:
        raise BagFormatError(f"{path}: cannot decompress it to {target} ({exc})") from exc
    return target
