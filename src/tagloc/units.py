"""Unit constants, defined once: time in tagloc is integer nanoseconds (``stamp_ns``)."""

from __future__ import annotations

#: Nanoseconds per second: ``duration_s = duration_ns / S_NS``.
S_NS = 1_000_000_000

__all__ = ["S_NS"]
