"""Deprecated location of the stream records: they live in :mod:`tagloc.messages`."""

from tagloc.messages import *  # noqa: F403
from tagloc.messages import __all__ as __all__
