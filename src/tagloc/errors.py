"""The tagloc exception hierarchy.

One root, :class:`TaglocError`, and one subclass per layer. The CLI turns any ``TaglocError`` into a
single line on stderr and exit code 1; any other exception is a bug and keeps its traceback.
Messages name the file, field, frame or message at fault so that one line is enough to act on.
"""

from __future__ import annotations


class TaglocError(Exception):
    """Root of every error tagloc raises on purpose."""


class GeometryError(TaglocError, ValueError):
    """A pose, rotation or point array is malformed (wrong shape, NaN, not a rotation)."""


class TransformLookupError(TaglocError, LookupError):
    """A transform between two frames cannot be produced."""


class UnknownFrameError(TransformLookupError):
    """A frame name that the buffer has never seen."""


class DisconnectedFramesError(TransformLookupError):
    """Two frames that live in different, unconnected trees."""


class ExtrapolationError(TransformLookupError):
    """A lookup time outside the buffered range (beyond the extrapolation tolerance)."""


class FrameTreeError(TaglocError, ValueError):
    """An edge that would break the tree (a second parent, a cycle, a self-edge)."""


class CameraModelError(TaglocError, ValueError):
    """A camera model that is malformed or does not match the data given to it."""


class ConfigError(TaglocError, ValueError):
    """A configuration or world file that fails validation; the message names file and field."""


class SimulationError(TaglocError):
    """A simulation that cannot be run as configured."""


class RecordError(TaglocError, ValueError):
    """A stream record (:mod:`tagloc.messages`) built with a malformed field."""
