"""Validation of the scalar and list fields that build a camera model.

Every failure raises :class:`~tagloc.errors.CameraModelError` whose message starts with the field
path given by the caller (``"cam0.intrinsics"``, ``"camera_info.K"``, ``"PinholeRadtan.fx"``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from numbers import Integral, Real
from typing import Any

import numpy as np
import numpy.typing as npt

from tagloc.config import short_repr
from tagloc.errors import CameraModelError


def get(mapping: Mapping[str, Any], keys: tuple[str, ...], where: str) -> Any:
    """The value of the first of ``keys`` present in ``mapping``.

    Raises
    ------
    CameraModelError
        ``"<where>: missing field '<keys[0]>'"`` if none is present.
    """
    for key in keys:
        if key in mapping:
            return mapping[key]
    raise CameraModelError(f"{where}: missing field '{keys[0]}'")


def positive_int(value: object, field: str) -> int:
    """``value`` as a positive ``int`` (a float with an integral value is accepted)."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise CameraModelError(f"{field}: expected a positive integer, got {short_repr(value)}")
    if isinstance(value, Integral):
        number = int(value)
    elif math.isfinite(float(value)) and float(value).is_integer():
        number = int(float(value))
    else:
        raise CameraModelError(f"{field}: expected a positive integer, got {short_repr(value)}")
    if number <= 0:
        raise CameraModelError(f"{field}: must be positive, got {number}")
    return number


def finite_float(value: object, field: str) -> float:
    """``value`` as a finite ``float``."""
    if isinstance(value, bool) or not isinstance(value, Real):
        raise CameraModelError(f"{field}: expected a number, got {short_repr(value)}")
    number = float(value)
    if not math.isfinite(number):
        raise CameraModelError(f"{field}: must be finite, got {number}")
    return number


def bounded(number: float, field: str, low: float, high: float, unit: str) -> float:
    """``number`` if ``low <= number <= high``; else a CameraModelError naming the range (the
    bounds keep projections of plausible cameras far from overflow)."""
    if not low <= number <= high:
        where = f"[{low:g}, {high:g}]" + (f" {unit}" if unit else "")
        raise CameraModelError(f"{field}: {number:g} is outside {where}")
    return number


def positive_float(value: object, field: str) -> float:
    """``value`` as a finite, strictly positive ``float``."""
    number = finite_float(value, field)
    if number <= 0.0:
        raise CameraModelError(f"{field}: must be positive, got {number}")
    return number


def float_list(value: object, field: str, counts: tuple[int, ...], what: str) -> list[float]:
    """``value`` (a list, tuple or 1-D array) as finite floats, of one of the allowed ``counts``.

    Parameters
    ----------
    value : object
        The raw field value.
    field : str
        Field path for messages.
    counts : tuple of int
        Allowed lengths.
    what : str
        What the length is for, e.g. ``"equidistant"``: the message reads
        ``"<field>: expected 4 values for equidistant, got 5"``.
    """
    if isinstance(value, np.ndarray) and value.ndim == 1:
        items: list[object] = list(value)
    elif isinstance(value, Sequence) and not isinstance(value, str | bytes):
        items = list(value)
    else:
        raise CameraModelError(f"{field}: expected a list of numbers, got {short_repr(value)}")
    if len(items) not in counts:
        expected = " or ".join(str(c) for c in counts)
        raise CameraModelError(f"{field}: expected {expected} values for {what}, got {len(items)}")
    return [finite_float(item, f"{field}[{i}]") for i, item in enumerate(items)]


def camera_matrix_values(K: npt.ArrayLike, field: str) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` of a 3x3 (or 9-value, row-major) zero-skew camera matrix.

    Raises
    ------
    CameraModelError
        If ``K`` does not have 9 values, is all zeros (an uncalibrated ROS camera), has a skew or a
        last row other than ``[0, 0, 1]``, or a non-positive focal length.
    """
    values = float_list(np.ravel(np.asarray(K, dtype=object)), field, (9,), "a 3x3 matrix")
    m = np.array(values).reshape(3, 3)
    if not m.any():
        raise CameraModelError(f"{field}: all zeros (the camera is not calibrated)")
    if m[0, 1] != 0.0:
        raise CameraModelError(f"{field}: skew [0][1] = {m[0, 1]:g} is not supported (must be 0)")
    if m[1, 0] != 0.0 or not np.array_equal(m[2], [0.0, 0.0, 1.0]):
        raise CameraModelError(
            f"{field}: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {m.tolist()}"
        )
    fx = positive_float(m[0, 0], f"{field}[0][0] (fx)")
    fy = positive_float(m[1, 1], f"{field}[1][1] (fy)")
    return fx, fy, float(m[0, 2]), float(m[1, 2])
