"""The tag map format's constants and bounds, its errors, and the checks that entries, maps and
the writer share: one-line validation errors, a covariance's symmetry and PSD, a quaternion's sign.
"""

from __future__ import annotations

import itertools
import re
from typing import Annotated, Any, TypeVar

import numpy as np
import numpy.typing as npt
import pydantic

from tagloc.config import FieldPathError, clip_message, one_line
from tagloc.errors import ConfigError, TaglocError

FORMAT_VERSION = 1
DEFAULT_FAMILY = "tag36h11"
MAP_FRAME = "map"
#: Sanity bounds: sizes in [1 mm, 5 m] catch millimetres typed as metres; coordinates +-100 km.
MIN_TAG_SIZE_M, MAX_TAG_SIZE_M, MAX_COORD_M = 1e-3, 5.0, 1e5
#: Largest covariance entry of a tag pose (m^2, rad^2): beyond it, products overflow downstream.
MAX_COVARIANCE = 1e4
_FRAME_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_./-]*")
_FLOOR_NAME = re.compile(r"[A-Za-z0-9_.+-]{1,64}")
_AXES = ("x", "y", "z", "rx", "ry", "rz")
ModelT = TypeVar("ModelT", bound=pydantic.BaseModel)
Path_ = tuple[str | int, ...]


class TagMapError(ConfigError):
    """A tag map that cannot be read or fails validation; the message names file, entry, field."""


class TagMapLookupError(TaglocError, LookupError):
    """A tag or frame that the map does not have."""


def _not_bool(value: object) -> object:
    if isinstance(value, bool):
        raise ValueError("must be a number, not true/false")
    return value


Real = Annotated[float, pydantic.BeforeValidator(_not_bool)]
Row6 = tuple[Real, Real, Real, Real, Real, Real]


def _validated(model: type[ModelT], data: dict[str, Any], source: str) -> ModelT:
    """``model.model_validate(data)``, failures as one line ``source: tags[4] (id 17): field``.

    Like :func:`tagloc.config.format_validation_error`, but the entry is named by index and id,
    and an unknown key is reported before the missing field it is probably a typo of.
    """
    try:
        return model.model_validate(data)
    except pydantic.ValidationError as exc:
        errors = exc.errors(include_url=False)
        first = next((e for e in errors if e["type"] == "extra_forbidden"), errors[0])
        loc, message = list(first["loc"]), first["msg"].removeprefix("Value error, ")
        if isinstance(error := first.get("ctx", {}).get("error"), FieldPathError):
            loc, message = loc + list(error.path), str(error)
        message = clip_message(message)
        parts = [source]
        if len(loc) > 1 and loc[0] == "tags" and isinstance(loc[1], int):
            tags = data.get("tags")
            item = tags[loc[1]] if isinstance(tags, list | tuple) else None
            tag_id = item.get("id") if isinstance(item, dict) else getattr(item, "id", None)
            parts.append(f"tags[{loc[1]}]" + (f" (id {tag_id})" if type(tag_id) is int else ""))
            loc = loc[2:]
        if loc:
            parts.append("".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in loc)[1:])
        n = len(errors) - 1
        more = f" (and {n} more error{'s' * (n > 1)})" if n else ""
        line = ": ".join([*parts, message[:1].lower() + message[1:]]) + more
        raise TagMapError(one_line(line)) from None


def _covariance_problem(cov: npt.NDArray[np.float64]) -> tuple[Path_, str] | None:
    """``(path, message)`` if ``cov`` (6, 6) is not symmetric PSD, else None.

    PSD is tested on the correlation matrix (units cancel): its least eigenvalue >= -1e-9.
    """
    variances = np.diag(cov)
    if (big := float(np.abs(cov).max())) > MAX_COVARIANCE:
        row, col = divmod(int(np.argmax(np.abs(cov))), 6)
        return (row, col), f"{big:.3g} is beyond {MAX_COVARIANCE:g} (a 100 m or rad sigma)"
    for i, j in itertools.combinations_with_replacement(range(6), 2):
        a, b = cov[i, j], cov[j, i]
        if i == j and a < 0:
            return (i, i), f"variance of {_AXES[i]} must be >= 0, got {a:.3g}"
        if abs(a - b) > 1e-9 * max(abs(a), abs(b)):
            return (i, j), f"not symmetric: {a:.6g}, but covariance[{j}][{i}] = {b:.6g}"
        if i != j and a != 0 and variances[i] * variances[j] == 0:
            return (i, j), f"{_AXES[i]}-{_AXES[j]} covariance {a:.3g} with a zero variance"
    scale = np.sqrt(np.where(variances > 0, variances, 1.0))
    least = float(np.linalg.eigvalsh(cov / np.outer(scale, scale))[0])
    if least < -1e-9:
        return (), f"not positive semi-definite (correlation matrix eigenvalue {least:.3g})"
    return None


def _canonical_sign(q: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    """``q`` or ``-q`` (the same rotation): ``w > 0``, or the first nonzero of x, y, z if w = 0."""
    sign = -1.0 if next((c for c in (q[3], *q[:3]) if c != 0.0), 0.0) < 0.0 else 1.0
    return (sign * q[0] + 0.0, sign * q[1] + 0.0, sign * q[2] + 0.0, sign * q[3] + 0.0)
