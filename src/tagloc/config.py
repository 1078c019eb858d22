"""Configuration files: strict YAML parsing, pydantic validation, one-line field-path errors.

Every human-edited file tagloc reads (``world.yaml``, ``tags.yaml``, ``localizer.yaml``) goes
through :func:`parse_yaml_mapping` and :func:`validate`, so all of them fail the same way: one
:class:`~tagloc.errors.ConfigError` line ``file: field.path: problem``, e.g.
``world.yaml: tags[3].size: field required`` or ``world.yaml: line 7, column 3: duplicate key
'tags' (first at line 2)``. YAML is parsed with a ``SafeLoader`` that also rejects duplicate keys
(plain ``yaml.safe_load`` silently keeps the last one, which would drop a whole ``tags:`` block).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Hashable
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

from tagloc.errors import ConfigError

#: Allowed deviation of a quaternion's norm from 1 in files (never silently normalized).
UNIT_QUAT_TOL = 1e-6

ModelT = TypeVar("ModelT", bound=BaseModel)


class StrictModel(BaseModel):
    """Base of file models: unknown keys, NaN and inf are errors; values are immutable."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class FieldPathError(ValueError):
    """A validation failure at ``path`` below the model whose validator raised it."""

    def __init__(self, path: tuple[str | int, ...], message: str) -> None:
        super().__init__(message)
        self.path = path


class _StrictLoader(yaml.SafeLoader):
    """``SafeLoader`` that rejects duplicate mapping keys."""


def _construct_mapping(loader: _StrictLoader, node: yaml.MappingNode) -> dict[Hashable, Any]:
    loader.flatten_mapping(node)
    seen: dict[Hashable, yaml.Mark] = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None,
                None,
                f"duplicate key {key!r} (first at line {seen[key].line + 1})",
                key_node.start_mark,
            )
        seen[key] = key_node.start_mark
    return loader.construct_mapping(node, deep=True)


_StrictLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def one_line(text: str) -> str:
    """Collapse all whitespace runs (newlines included) to single spaces."""
    return " ".join(text.split())


def parse_yaml_mapping(text: str, source: str) -> dict[str, Any]:
    """Parse YAML text whose top level must be a mapping; ``source`` names it in errors.

    Raises
    ------
    ConfigError
        ``source: line L, column C: invalid YAML: ...``, duplicate keys, or a non-mapping top level.
    """
    try:
        data = yaml.load(text, Loader=_StrictLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        context, start = getattr(exc, "context", None), getattr(exc, "context_mark", None)
        if context and start is not None and start is not mark:
            problem += f" ({context} started at line {start.line + 1})"
        raise ConfigError(one_line(f"{source}: {where}invalid YAML: {problem}")) from None
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: the top level must be a mapping, got {type(data).__name__}")
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
            f"unknown value {ctx['tag']!r}; allowed: {ctx['expected_tags']}"
            if first["type"] == "union_tag_invalid"
            else "field required"
        )
    msg = msg.removeprefix("Value error, ")
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
