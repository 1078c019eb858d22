"""TUM trajectory files: one pose per line, ``timestamp tx ty tz qx qy qz qw``.

The format of the TUM RGB-D benchmark, read by evo (``evo_ape tum ...``): the timestamp in
seconds, the position of the body in the trajectory's frame in metres, and its orientation as a
unit quaternion ``quat_xyzw``; fields separated by one space, ``#`` starts a comment line.
:func:`write_tum` writes the timestamp with exactly 9 decimals (integer nanoseconds, no float
rounding), every other value with the shortest repr that reads back bit-exactly, quaternions with
``w >= 0``, and a ``#`` header line. :func:`read_tum` also accepts other writers' files
(``%.18e`` from evo, 4 decimals from the TUM benchmark): any whitespace, timestamps in any decimal
or exponent notation (converted to ns exactly), quaternions renormalized within ``quat_tol``.
It refuses what would overflow later: files over :data:`MAX_TUM_BYTES`, positions beyond
:data:`MAX_POSITION_M` (squared errors of 1e308 are ``inf``) and stamps past the int64 nanosecond
range.
"""

from __future__ import annotations

import math
import os
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np
import numpy.typing as npt

from tagloc.config import MAX_QUOTED_CHARS, read_text_file, short_repr
from tagloc.fileutil import atomic_write_text
from tagloc.geometry import SE3
from tagloc.io.errors import InputNotFoundError, TrajectoryFileError

Int64Array = npt.NDArray[np.int64]
#: Largest trajectory file read, bytes (about 600 000 poses).
MAX_TUM_BYTES = 64 * 2**20
#: Largest accepted position coordinate, m (beyond any building or UTM zone; far from overflow).
MAX_POSITION_M = 1e8
_MAX_SECONDS = Decimal(np.iinfo(np.int64).max) / 1_000_000_000
TUM_HEADER = "# timestamp[s] tx ty tz qx qy qz qw (tagloc: body pose in the trajectory frame)\n"


def write_tum(path: str | os.PathLike[str], stamps_ns: npt.ArrayLike, T_map_base: SE3) -> None:
    """Write a trajectory atomically (temporary file beside ``path``, then rename).

    Parameters
    ----------
    path : str or PathLike
        The ``.txt``/``.tum`` file; replaced if it exists.
    stamps_ns : (N,) int
        Integer nanoseconds, ``>= 0``, strictly increasing.
    T_map_base : SE3, batch of N (or single when N = 1)
        Pose of the body in the trajectory's frame at each stamp.

    Raises
    ------
    TrajectoryFileError
        If the stamps are not integers, negative, not strictly increasing, or their count
        differs from the number of poses; the message names ``path``.
    """
    path = Path(path)
    stamps = np.asarray(stamps_ns)
    if stamps.ndim == 0:
        stamps = stamps.reshape(1)
    if stamps.ndim != 1 or stamps.dtype.kind not in "iu":
        raise TrajectoryFileError(
            f"{path}: stamps_ns must be a 1-D array of integer nanoseconds, got "
            f"{stamps.dtype} of shape {stamps.shape}"
        )
    poses = T_map_base if T_map_base.is_batch else SE3.stack([T_map_base])
    if len(poses) != len(stamps):
        raise TrajectoryFileError(f"{path}: {len(stamps)} stamps but {len(poses)} poses")
    if len(stamps) and stamps.min() < 0:
        raise TrajectoryFileError(f"{path}: negative stamp {int(stamps.min())} ns")
    if (bad := np.flatnonzero(np.diff(stamps) <= 0)).size:
        i = int(bad[0])
        raise TrajectoryFileError(
            f"{path}: stamps must increase strictly: stamps_ns[{i + 1}] = {int(stamps[i + 1])} "
            f"after stamps_ns[{i}] = {int(stamps[i])}"
        )
    values = np.hstack([poses.translation, poses.as_quat()]).tolist()
    lines = [tum_line(s, row) for s, row in zip(stamps.tolist(), values, strict=True)]
    atomic_write_text(path, TUM_HEADER + "".join(lines))


def tum_line(stamp_ns: int, values: list[float]) -> str:
    """One TUM line: the stamp with 9 decimals, then ``tx ty tz qx qy qz qw`` (``values``) in
    the shortest repr that reads back exactly."""
    return f"{stamp_ns // 1_000_000_000}.{stamp_ns % 1_000_000_000:09d} " + " ".join(
        map(repr, values)
    ) + "\n"


def read_tum(path: str | os.PathLike[str], *, quat_tol: float = 1e-3) -> tuple[Int64Array, SE3]:
    """Read a trajectory file.

    Parameters
    ----------
    path : str or PathLike
    quat_tol : float
        Largest accepted ``| |q| - 1 |``; quaternions within it are renormalized (files from
        other tools round to a few decimals).

    Returns
    -------
    stamps_ns : (N,) int64
        The timestamps, rounded to the nanosecond.
    T_map_base : SE3, batch of N
        The poses, in the file's frame.

    Raises
    ------
    InputNotFoundError
        If ``path`` does not exist.
    TrajectoryFileError
        ``"<path>: line <n>: ..."`` for a line without 8 numbers, a non-finite value, a position
        beyond :data:`MAX_POSITION_M`, a negative timestamp or one past the int64 nanosecond
        range, a timestamp not after the previous one, or a quaternion off unit norm by more than
        ``quat_tol``; or a file with no pose, larger than :data:`MAX_TUM_BYTES` or not UTF-8.
    """
    path = Path(path)
    if not path.exists():
        raise InputNotFoundError(f"{path}: no such trajectory file")
    text = read_text_file(
        path, "the trajectory file", max_bytes=MAX_TUM_BYTES, error=TrajectoryFileError
    )
    stamps: list[int] = []
    rows: list[list[float]] = []
    previous_line = 0
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        where = f"{path}: line {number}"
        stamp, row = _parse(fields, where, quat_tol)
        if stamps and stamp <= stamps[-1]:
            raise TrajectoryFileError(
                f"{where}: timestamp {_cut(fields[0])} is not after the one on line "
                f"{previous_line} (stamps must increase strictly)"
            )
        stamps.append(stamp)
        rows.append(row)
        previous_line = number
    if not rows:
        raise TrajectoryFileError(f"{path}: no pose in the file (expected lines 'timestamp tx ty "
                                  "tz qx qy qz qw')")  # fmt: skip
    values = np.array(rows)
    return np.array(stamps, dtype=np.int64), SE3.from_quat(values[:, 3:], values[:, :3])


def _parse(fields: list[str], where: str, quat_tol: float) -> tuple[int, list[float]]:
    """One line's stamp (ns) and ``[tx, ty, tz, qx, qy, qz, qw]`` with a normalized quaternion."""
    if len(fields) != 8:
        raise TrajectoryFileError(
            f"{where}: expected 8 values 'timestamp tx ty tz qx qy qz qw', got {len(fields)}"
        )
    try:
        seconds = Decimal(fields[0])
        values = [float(v) for v in fields[1:]]
    except (InvalidOperation, ValueError):
        raise TrajectoryFileError(f"{where}: not a number among {short_repr(fields)}") from None
    if not seconds.is_finite() or not all(map(math.isfinite, values)):
        raise TrajectoryFileError(f"{where}: NaN or infinite value among {short_repr(fields)}")
    if seconds < 0:
        raise TrajectoryFileError(f"{where}: negative timestamp {_cut(fields[0])}")
    if seconds > _MAX_SECONDS:
        raise TrajectoryFileError(
            f"{where}: timestamp {_cut(fields[0])} is past the int64 nanosecond range"
        )
    if (big := max(abs(v) for v in values[:3])) > MAX_POSITION_M:
        raise TrajectoryFileError(
            f"{where}: position coordinate {big:g} m is beyond {MAX_POSITION_M:g} m (tx ty tz)"
        )
    norm = math.sqrt(sum(v * v for v in values[3:]))
    if abs(norm - 1.0) > quat_tol:
        raise TrajectoryFileError(
            f"{where}: quaternion (qx qy qz qw) = {short_repr(fields[4:])} is not unit: "
            f"|q| = {norm:.9g} (tolerance {quat_tol:g})"
        )
    stamp = int((seconds * 1_000_000_000).to_integral_value())
    return stamp, values[:3] + [v / norm for v in values[3:]]


def _cut(text: str) -> str:
    """``text`` as quoted in messages: at most :data:`tagloc.config.MAX_QUOTED_CHARS` characters."""
    return text if len(text) <= MAX_QUOTED_CHARS else text[: MAX_QUOTED_CHARS - 3] + "..."
