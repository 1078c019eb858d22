"""Errors of the ``tagloc.io`` layer (bags, MCAP files, trajectory files, stream records).

:class:`TaglocIOError` is this layer's subclass of :class:`tagloc.errors.TaglocError`; the CLI turns
it into one line and exit code 1. Every message starts with the file it is about, then the topic,
message index, line or field at fault (``"drive.bag: /odom message 12: ..."``).
"""

from __future__ import annotations

from tagloc.errors import RecordError, TaglocError

__all__ = [
    "BagFormatError",
    "BagTopicError",
    "BagWriteError",
    "InputNotFoundError",
    "RecordError",
    "TaglocIOError",
    "TrajectoryFileError",
]


class TaglocIOError(TaglocError):
    """Root of every error ``tagloc.io`` raises on purpose."""


class InputNotFoundError(TaglocIOError, FileNotFoundError):
    """A bag, MCAP or trajectory path that does not exist."""


class BagFormatError(TaglocIOError, ValueError):
    """A bag that cannot be read as asked.

    Damaged or truncated files, a storage format or message type tagloc does not read, a message
    that breaks the rules under ``on_bad="error"``, or a reader option that does not fit the data
    (a corner order whose winding is mirrored, a missing tag family).
    """


class BagTopicError(BagFormatError, LookupError):
    """A requested topic that the bag does not hold; the message lists the topics it does hold."""


class BagWriteError(TaglocIOError):
    """A bag that cannot be written: the target exists, a record does not fit its topic."""


class TrajectoryFileError(TaglocIOError, ValueError):
    """A TUM trajectory file that cannot be read or written; the message names file and line."""
