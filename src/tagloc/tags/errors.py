"""Errors of the ``tagloc.tags`` layer (detection, tag bitmaps).

:class:`TagError` is this layer's subclass of :class:`tagloc.errors.TaglocError`; the CLI turns it
into one line and exit code 1. Messages name the argument, field or option at fault.
"""

from __future__ import annotations

from tagloc.errors import TaglocError


class TagError(TaglocError):
    """Root of every error ``tagloc.tags`` raises on purpose."""


class TagInputError(TagError, ValueError):
    """An image or a corner array that cannot be used (empty, wrong dtype, shape or channels)."""


class TagBackendError(TagError, ValueError):
    """An unknown backend or family, a family the backend cannot detect, or a bad option."""
