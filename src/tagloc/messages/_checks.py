"""Validation helpers of the stream's records: each checks one field in ``__post_init__`` and
raises a :class:`~tagloc.errors.RecordError` naming the record and the field."""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import RecordError
from tagloc.geometry import SE3


def _set(record: object, name: str, value: object) -> None:
    object.__setattr__(record, name, value)


def _describe(value: object) -> str:
    if isinstance(value, np.ndarray):
        return f"{value.dtype} array of shape {value.shape}"
    return type(value).__name__


def _stamp(record: Any) -> int:
    value = record.stamp_ns
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise RecordError(
            f"{type(record).__name__}.stamp_ns: expected int nanoseconds, got {_describe(value)}"
        )
    if value < 0:
        raise RecordError(f"{type(record).__name__}.stamp_ns: must be >= 0, got {value}")
    return int(value)


def _frame(record: Any, name: str) -> str:
    value = getattr(record, name)
    if not isinstance(value, str):
        raise RecordError(f"{type(record).__name__}.{name}: expected a str, got {_describe(value)}")
    return value


def _check_stamp_frame(record: Any) -> None:
    _set(record, "stamp_ns", _stamp(record))
    _frame(record, "frame_id")  # may be empty: ROS allows it


def _pose(record: Any, name: str) -> SE3:
    value = getattr(record, name)
    if not isinstance(value, SE3) or value.batch_shape != ():
        raise RecordError(
            f"{type(record).__name__}.{name}: expected a single SE3, got "
            f"{'a batch' if isinstance(value, SE3) else _describe(value)}"
        )
    return value


def _array(record: Any, name: str, shape: tuple[int, ...]) -> FloatArray:
    where = f"{type(record).__name__}.{name}"
    try:
        array = np.array(getattr(record, name), dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise RecordError(f"{where}: cannot be read as a float array ({exc})") from None
    if array.shape != shape:
        raise RecordError(f"{where}: expected shape {shape}, got {array.shape}")
    if not np.isfinite(array).all():
        raise RecordError(f"{where}: holds NaN or infinite values")
    array.flags.writeable = False
    return array


def _float32(record: Any, name: str) -> npt.NDArray[np.float32]:
    """A read-only float32 copy of an array field (a read-only float32 array is kept as is)."""
    value = getattr(record, name)
    where = f"{type(record).__name__}.{name}"
    if isinstance(value, np.ndarray) and value.dtype == np.float32 and not value.flags.writeable:
        return value
    try:
        array = np.array(value, dtype=np.float32)
    except (TypeError, ValueError) as exc:
        raise RecordError(f"{where}: cannot be read as a float32 array ({exc})") from None
    array.flags.writeable = False
    return array


def _frozen(value: Any) -> Any:
    """Lists and arrays to tuples of float/int, mappings to read-only mappings (recursively)."""
    if isinstance(value, Mapping):
        return MappingProxyType({str(k): _frozen(v) for k, v in value.items()})
    if isinstance(value, np.ndarray):
        return tuple(value.reshape(-1).tolist())
    if isinstance(value, (list, tuple)):
        return tuple(_frozen(v) for v in value)
    if isinstance(value, np.generic):
        return value.item()
    return value
