"""Argument checks and message formatting for :mod:`tagloc.frames` (inputs are checked once, at
the public entry points)."""

from __future__ import annotations

import math
from typing import TypeAlias

import numpy as np
import numpy.typing as npt

from tagloc.errors import FrameTreeError, GeometryError
from tagloc.frames.errors import StampError
from tagloc.geometry import SE3

IntArray: TypeAlias = npt.NDArray[np.int64]

_INT64_MIN, _INT64_MAX = -(2**63), 2**63 - 1
_NS_PER_S = 1_000_000_000


def stamp(value: object, name: str = "stamp_ns") -> int:
    """``value`` as a Python int of nanoseconds, or :class:`StampError`."""
    if type(value) is int:
        out = value
    elif isinstance(value, np.integer):
        out = int(value)
    else:
        hint = " (seconds? use int(round(t_s * 1e9)))" if isinstance(value, float) else ""
        raise StampError(
            f"{name} must be an integer number of nanoseconds, got "
            f"{type(value).__name__} {value!r}{hint}"
        )
    if not _INT64_MIN <= out <= _INT64_MAX:
        raise StampError(f"{name} = {out} is outside the int64 range of nanoseconds")
    return out


def stamps(value: object, name: str = "stamps_ns") -> IntArray:
    """``value`` as a non-empty 1-D ``int64`` array (a copy), or :class:`StampError`."""
    array = np.asarray(value)
    if array.dtype == np.bool_ or not np.issubdtype(array.dtype, np.integer):
        raise StampError(
            f"{name} must be an integer (int64) array of nanoseconds, got dtype {array.dtype}"
        )
    if array.ndim != 1 or array.size == 0:
        raise StampError(f"{name} must be a non-empty 1-D array, got shape {array.shape}")
    if array.dtype == np.uint64 and int(array.max()) > _INT64_MAX:
        raise StampError(f"{name} holds {int(array.max())}, outside the int64 range")
    return np.array(array, dtype=np.int64)


def frame(value: object, name: str) -> str:
    """A frame name: a non-empty ``str``, or :class:`FrameTreeError`."""
    if not isinstance(value, str) or not value:
        raise FrameTreeError(f"{name} must be a non-empty frame name (str), got {value!r}")
    return value


def single_pose(T: object, parent: str, child: str) -> list[float]:
    """One finite :class:`SE3` as the 12 floats ``[R row-major, t]``, or :class:`GeometryError`
    naming the edge ``parent -> child``."""
    if not isinstance(T, SE3):
        raise GeometryError(
            f"edge {parent!r} -> {child!r}: expected an SE3, got {type(T).__name__}"
        )
    if T.translation.ndim != 1:
        raise GeometryError(
            f"edge {parent!r} -> {child!r}: expected a single SE3, got a batch of {len(T)} "
            "(use set_transforms)"
        )
    values: list[float] = T.rotation.as_matrix().ravel().tolist() + T.translation.tolist()
    if not all(map(math.isfinite, values)):
        raise GeometryError(f"edge {parent!r} -> {child!r}: the transform contains NaN or inf")
    return values


def pose_batch(T: object, n: int, parent: str, child: str) -> SE3:
    """A finite batch of ``n`` :class:`SE3` (or one, for ``n == 1``), or :class:`GeometryError`."""
    what = f"edge {parent!r} -> {child!r}"
    if not isinstance(T, SE3):
        raise GeometryError(f"{what}: expected an SE3 batch, got {type(T).__name__}")
    count = len(T) if T.translation.ndim == 2 else 1
    if count != n:
        raise GeometryError(f"{what}: {n} stamps but {count} transforms")
    if not (np.isfinite(T.rotation.as_matrix()).all() and np.isfinite(T.translation).all()):
        bad = np.flatnonzero(~np.isfinite(np.reshape(T.translation, (-1, 3))).all(axis=1))
        rbad = np.flatnonzero(~np.isfinite(np.reshape(T.rotation.as_matrix(), (-1, 9))).all(axis=1))
        first = int(np.concatenate([bad, rbad]).min())
        raise GeometryError(f"{what}: the transforms contain NaN or inf (first at index {first})")
    return T


def seconds(stamp_ns: int) -> str:
    """``stamp_ns`` as seconds with 9 decimals, exact (no float rounding): ``"12.000000001"``."""
    whole, frac = divmod(abs(stamp_ns), _NS_PER_S)
    return f"{'-' if stamp_ns < 0 else ''}{whole}.{frac:09d}"


def span(stamp_ns: int) -> str:
    """``"1.500000000 s (1500000000 ns)"``."""
    return f"{seconds(stamp_ns)} s ({stamp_ns} ns)"
