"""What a bag message decodes to: records or :class:`Bad` content, and the decoding options
(shared by :mod:`tagloc.io.convert` and :mod:`tagloc.io.convert_cloud`)."""

from __future__ import annotations

from typing import Any, Literal, NamedTuple

from tagloc.config import StrictModel
from tagloc.messages import Message
from tagloc.tags.detection import TAGLOC_ORDER

__all__ = ["Bad", "DecodeOptions", "Decoded", "stamp_of"]


class Bad(NamedTuple):
    """Content that breaks a rule: ``reason`` is the key of the reader's ``skipped`` counter."""

    reason: str
    detail: str


class DecodeOptions(StrictModel):
    """How the reader turns messages into records (see :class:`tagloc.io.BagSource`)."""

    stamp: Literal["header", "log"] = "header"
    corner_order: str = TAGLOC_ORDER
    pixel_offset: float = 0.0
    default_family: str | None = None
    quat_tol: float = 1e-3


Decoded = list[Message | Bad]


def stamp_of(header: Any, log_ns: int, opts: DecodeOptions) -> int:
    if opts.stamp == "log":
        return log_ns
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
