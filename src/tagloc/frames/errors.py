"""Errors of :mod:`tagloc.frames` that :mod:`tagloc.errors` has no class for.

The frames layer otherwise raises the shared classes: :class:`~tagloc.errors.UnknownFrameError`,
:class:`~tagloc.errors.DisconnectedFramesError`, :class:`~tagloc.errors.ExtrapolationError`
(all :class:`~tagloc.errors.TransformLookupError`), :class:`~tagloc.errors.FrameTreeError` and
:class:`~tagloc.errors.GeometryError`.
"""

from __future__ import annotations

from tagloc.errors import TaglocError


class StampError(TaglocError, TypeError):
    """A stamp that is not integer nanoseconds (a float, a bool, a non-integer array, or out of
    the int64 range)."""


class StaleSampleError(TaglocError, ValueError):
    """A dynamic sample older than the edge's newest sample minus the buffer window."""
