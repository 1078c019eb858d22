"""The evaluation layer's exception."""

from __future__ import annotations

from tagloc.errors import TaglocError


class EvaluationError(TaglocError, ValueError):
    """Trajectories that cannot be compared (different lengths, stamps, NaN, degenerate)."""
