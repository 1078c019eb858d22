"""Configuration files: strict YAML parsing, pydantic validation, one-line field-path errors.

Every human-edited file tagloc reads (``world.yaml``, ``tags.yaml``, ``localizer.yaml``) goes
through :func:`read_text_file`, :func:`parse_yaml_mapping` and :func:`validate`, so all of them
fail the same way: one :class:`~tagloc.errors.ConfigError` line ``file: field.path: problem``, e.g.
``world.yaml: tags[3].size: field required`` or ``world.yaml: line 7, column 3: duplicate key
'tags' (first at line 2)``. YAML is parsed with a safe loader that also rejects duplicate keys
(plain ``yaml.safe_load`` silently keeps the last one, which would drop a whole ``tags:`` block).

Every input is bounded before anything walks it: files larger than :data:`MAX_YAML_BYTES`, text
that is not UTF-8, documents nested deeper than :data:`MAX_YAML_DEPTH` and documents that expand
(through ``&anchor`` / ``*alias``) to more than :data:`MAX_YAML_NODES` values are refused with one
line; a bad value is quoted by at most :data:`MAX_QUOTED_CHARS` characters (:func:`short_repr`).
"""

from __future__ import annotations

import math
import os
import reprlib
from collections.abc import Collection
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from tagloc._yaml_loader import MAX_YAML_DEPTH as MAX_YAML_DEPTH  # re-exported: the limits
from tagloc._yaml_loader import MAX_YAML_NODES as MAX_YAML_NODES  # of every config file
from tagloc._yaml_loader import StrictLoader
from tagloc.errors import ConfigError, TaglocError

#: Allowed deviation of a quaternion's norm from 1 in files (never silently normalized).
UNIT_QUAT_TOL = 1e-6
#: Largest YAML file or text read, bytes (a tag map of 10 000 tags is about 2 MB).
MAX_YAML_BYTES = 4 * 2**20
#: Most threads a native library (small_gicp, the AprilTag detector) may be asked for: above any
#: robot's cores, below counts that crash a thread pool.
MAX_THREADS = 64
#: Longest quotation of a bad value in an error message, characters.
MAX_QUOTED_CHARS = 60
#: Longest problem description of a validation error, characters (a backstop for validators).
_MAX_MESSAGE_CHARS = 240

ModelT = TypeVar("ModelT", bound=BaseModel)


class StrictModel(BaseModel):
    """Base of file models: unknown keys, NaN and inf are errors; values are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class FieldPathError(ValueError):
    """A validation failure at ``path`` below the model whose validator raised it."""

    def __init__(self, path: tuple[str | int, ...], message: str) -> None:
        super().__init__(message)
        self.path = path


def one_line(text: str) -> str:
    """Collapse all whitespace runs (newlines included) to single spaces."""
    return " ".join(text.split())


def clip_message(problem: str) -> str:
    """``problem`` cut to 240 characters: a backstop for validators that quote whole values."""
    return (
        problem if len(problem) <= _MAX_MESSAGE_CHARS else problem[: _MAX_MESSAGE_CHARS - 3] + "..."
    )


def short_repr(value: object, limit: int = MAX_QUOTED_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters (``...`` at the end), never built in full."""
    text = _SHORT_REPR.repr(value)
    return text if len(text) <= limit else text[: max(limit - 3, 0)] + "..."


_SHORT_REPR = reprlib.Repr()
_SHORT_REPR.maxlevel, _SHORT_REPR.maxlist, _SHORT_REPR.maxtuple, _SHORT_REPR.maxdict = 3, 6, 6, 4
_SHORT_REPR.maxstring = _SHORT_REPR.maxother = _SHORT_REPR.maxlong = MAX_QUOTED_CHARS + 2


def read_text_file(
    path: str | os.PathLike[str],
    what: str,
    *,
    max_bytes: int = MAX_YAML_BYTES,
    error: type[TaglocError] = ConfigError,
) -> str:
    """The UTF-8 text of ``path``, refusing files larger than ``max_bytes``.

    Parameters
    ----------
    path : str or PathLike
    what : str
        What the file is, for messages (``"world file"``).
    max_bytes : int
        Largest accepted size; a larger file is refused before it is read in full.
    error : type of TaglocError
        The exception raised (the caller's layer).

    Raises
    ------
    TaglocError
        Of type ``error``, one line naming ``path``: it cannot be read (missing, a directory, no
        permission), is larger than ``max_bytes``, or is not UTF-8 (with the byte offset).
    """
    name = os.fspath(path)
    try:
        with open(path, "rb") as handle:
            data = handle.read(max_bytes + 1)
    except OSError as exc:
        raise error(f"{name}: cannot read {what}: {exc.strerror or exc}") from None
    if len(data) > max_bytes:
        raise error(f"{name}: {what} is larger than {max_bytes} bytes; refusing to read it")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(
            f"{name}: {what} is not UTF-8 text: byte 0x{data[exc.start]:02x} at offset {exc.start}"
        ) from None


def parse_yaml_mapping(text: str, source: str) -> dict[str, Any]:
    """Parse YAML text whose top level must be a mapping; ``source`` names it in errors.

    Raises
    ------
    ConfigError
        As :func:`parse_yaml`, or a top level that is not a mapping.
    """
    data = parse_yaml(text, source)
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: the top level must be a mapping, got {type(data).__name__}")
    return data


def parse_yaml(text: str, source: str) -> Any:
    """Parse YAML text (any top level; ``None`` for an empty document), bounded and strict.

    Raises
    ------
    ConfigError
        ``source: line L, column C: invalid YAML: ...``, duplicate keys, nesting deeper than
        :data:`MAX_YAML_DEPTH`, more than :data:`MAX_YAML_NODES` values after alias expansion, or
        a text longer than :data:`MAX_YAML_BYTES`.
    """
    if len(text) > MAX_YAML_BYTES:
        raise ConfigError(
            f"{source}: longer than {MAX_YAML_BYTES} characters; refusing to parse it"
        )
    try:
        data = yaml.load(text, Loader=StrictLoader)
    except RecursionError:  # only without libyaml: the pure-Python composer recurses per level
        raise ConfigError(f"{source}: invalid YAML: nested too deeply") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        context, start = getattr(exc, "context", None), getattr(exc, "context_mark", None)
        if context and start is not None and start is not mark:
            problem += f" ({context} started at line {start.line + 1})"
        raise ConfigError(one_line(f"{source}: {where}invalid YAML: {problem}")) from None
    return data


def format_validation_error(
    source: str, exc: ValidationError, union_tags: Collection[str] = ()
) -> str:
    """The first error of ``exc`` as ``source: a.b[3].c: message (and N more errors)``.

    ``union_tags`` are the discriminator values of tagged unions: pydantic puts the chosen tag into
    the error location (``robot.odometry.legged.scale_error``); they are dropped from the path.
    """
    errors = exc.errors(include_url=False)
    first = errors[0]
    loc, msg, ctx = list(first["loc"]), first["msg"], first.get("ctx", {})
    if isinstance(ctx.get("error"), FieldPathError):
        loc, msg = loc + list(ctx["error"].path), str(ctx["error"])
    elif first["type"] in ("union_tag_invalid", "union_tag_not_found"):
        loc.append(ctx["discriminator"].strip("'"))
        msg = (
            f"unknown value {short_repr(ctx['tag'])}; allowed: {ctx['expected_tags']}"
            if first["type"] == "union_tag_invalid"
            else "field required"
        )
    msg = clip_message(msg.removeprefix("Value error, "))
    loc = [p for k, p in enumerate(loc) if not (k and p in union_tags)]
    path = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in loc).lstrip(".")
    more = (
        f" (and {len(errors) - 1} more error{'s' * (len(errors) > 2)})" if len(errors) > 1 else ""
    )
    return one_line(f"{source}: {path + ': ' if path else ''}{msg[:1].lower()}{msg[1:]}{more}")


def validate(
    model: type[ModelT], data: dict[str, Any], source: str, union_tags: Collection[str] = ()
) -> ModelT:
    """``model.model_validate(data)`` with failures as one-line :class:`ConfigError`."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(format_validation_error(source, exc, union_tags)) from None


def check_unit_quat(
    quat_xyzw: tuple[float, float, float, float],
) -> tuple[float, float, float, float]:
    """Return ``quat_xyzw`` unchanged if its norm is 1 within :data:`UNIT_QUAT_TOL`, else raise."""
    norm = math.sqrt(sum(c * c for c in quat_xyzw))
    if abs(norm - 1.0) > UNIT_QUAT_TOL:
        raise ValueError(
            f"not a unit quaternion: |q| = {norm:.9g} (tolerance {UNIT_QUAT_TOL:g}); "
            "write it normalized"
        )
    return quat_xyzw
