"""Read ROS 1 bags, ROS 2 bags and MCAP files as a stream of tagloc records.

:class:`BagSource` is a :class:`~tagloc.messages.MessageSource` over ``rosbags``'
``AnyReader``: ``for topic, msg in BagSource("drive.bag"): ...``.

Decisions
---------
Order and stamps
    Items come in the bag's *log-time* order (the order ``AnyReader`` merges them in; re-sorting
    by header stamp is out of scope). Each record's ``stamp_ns`` is the message's *header stamp*
    (the time the data refers to, what the transform buffer and the filter need), or the log time
    with ``stamp="log"``. Per topic (per child frame on ``/tf``) header stamps must increase
    strictly: a duplicate or an earlier stamp is a bad item (``duplicate_stamp``,
    ``stamp_backwards``). ``/tf_static`` (any topic whose last name part is ``tf_static``) yields
    ``static=True`` transforms and is exempt.
Bad content
    Each item that breaks a rule is handled per ``on_bad``: ``"skip"`` (default) drops it,
    counts it in :attr:`BagSource.skipped` under its reason and logs a warning (once per topic and
    reason, then a summary at the end); ``"error"`` raises :class:`BagFormatError`. An item is a
    message, one transform of a ``TFMessage``, or one detection of a tag array (the array itself
    is kept). Reasons: ``non_finite`` (NaN/inf pose, covariance or twist), ``bad_quaternion``,
    ``duplicate_stamp``, ``stamp_backwards``, ``bad_detection``, ``unknown_family``,
    ``unsupported_encoding``, ``bad_image``, ``bad_point_cloud``, ``undecodable``,
    ``invalid_record``.
Options that do not fit the data
    are always errors: a ``corner_order`` whose corners come out mirrored, an empty tag family
    without ``default_family``.
Damaged files
    A missing path is :class:`InputNotFoundError`; a file that cannot be opened or whose data
    breaks off (a truncated recording, a bad chunk) is a one-line :class:`BagFormatError` naming
    the file. The damaged tail is not salvaged: ``rosbags`` needs the bag index, so repair the
    file first (``rosbag reindex``, ``mcap recover``).
Compressed files
    ``*.bag.bz2`` / ``*.mcap.bz2`` (a whole file compressed, as the dupont data set ships) are
    decompressed once (:func:`~tagloc.io.bag_open.open_bag`) into a cache
    (``<tmp>/tagloc-bags-<uid>/``, keyed by path, size and mtime; the source is never touched).
    Compressed chunks inside a ROS 1 bag (bz2, lz4) and zstd ROS 2 bags are read directly.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Literal, NamedTuple

from tagloc.config import validate
from tagloc.io.bag_open import BAG_KINDS, open_bag
from tagloc.io.convert import DECODERS, decode, make_typestore
from tagloc.io.decoded import Bad, DecodeOptions
from tagloc.io.errors import BagFormatError, BagTopicError, RecordError
from tagloc.messages import Message, TransformMsg
from tagloc.tags.detection import TAGLOC_ORDER, corner_permutation
from tagloc.tags.families import family_spec

__all__ = ["BagSource", "BagTopic", "open_bag"]

logger = logging.getLogger(__name__)

OnBad = Literal["skip", "error"]


class BagTopic(NamedTuple):
    """One topic of a bag: its ROS type (``rosbags`` spelling, ``nav_msgs/msg/Odometry``) and
    message count."""

    msgtype: str
    msgcount: int


class _Selected(NamedTuple):
    name: str  # stream topic
    record: type[Message]
    static: bool


class BagSource:
    """A bag, ROS 2 bag or MCAP file as a :class:`~tagloc.messages.MessageSource`.

    Parameters
    ----------
    path : str or PathLike
        See :func:`open_bag`.
    topics : Mapping[str, str] or Sequence[str], optional
        Bag topics to read, each mapped to the topic name it gets in the stream (a sequence keeps
        the names). Default: every topic whose type tagloc reads (others are logged and left out).
        Supported types: ``nav_msgs/Odometry``, ``sensor_msgs/Image`` (mono8, 8UC1, bgr8, rgb8),
        ``sensor_msgs/CompressedImage``, ``sensor_msgs/CameraInfo``, ``sensor_msgs/PointCloud2``
        (as :class:`PointCloudMsg`), ``tf2_msgs/TFMessage``,
        ``geometry_msgs/PoseWithCovarianceStamped``, ``geometry_msgs/PoseStamped`` (as
        :class:`GroundTruthMsg`), ``apriltag_msgs/ApriltagArrayStamped`` (ROS 1) and
        ``apriltag_msgs/AprilTagDetectionArray`` (ROS 2); conversions in
        :mod:`tagloc.io.convert`.
    stamp : {"header", "log"}
        The source of ``stamp_ns`` (module docstring).
    on_bad : {"skip", "error"}
        What bad content does (module docstring).
    corner_order : str
        How the bag lists tag corners (labels ``tl, tr, br, bl`` joined by ``_``, see
        :meth:`TagDetection.from_corners`); default tagloc's own order, which :class:`BagSink`
        writes. The AprilTag 3 C library lists ``"bl_br_tr_tl"`` with ``pixel_offset=0.5``.
    pixel_offset : float
        The coordinate the bag gives the centre of the top-left pixel (0.0 OpenCV).
    default_family : str, optional
        Tag family for detections whose ``family`` field is empty (the dupont bag's are).
    quat_tol : float
        Largest accepted ``| |q| - 1 |`` of a message's quaternion; within it, q is renormalized.
    cache_dir : str or PathLike, optional
        See :func:`open_bag`.

    Attributes
    ----------
    path : Path
        As given.
    bag_topics : dict of str to BagTopic
        Every topic in the file, read or not.
    start_ns, end_ns : int
        Log time of the first message and just after the last (0, 0 for an empty bag).
    skipped : dict of str to int
        Items dropped during the latest iteration, by reason (reset when iteration starts).

    Raises
    ------
    InputNotFoundError, BagFormatError
        From :func:`open_bag`, or when the file cannot be opened (damaged, truncated, a storage
        format ``rosbags`` does not read), or a requested topic has a type tagloc does not read.
    BagTopicError
        If a requested topic is not in the bag (the message lists the bag's topics and types).
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        topics: Mapping[str, str] | Sequence[str] | None = None,
        *,
        stamp: Literal["header", "log"] = "header",
        on_bad: OnBad = "skip",
        corner_order: str = TAGLOC_ORDER,
        pixel_offset: float = 0.0,
        default_family: str | None = None,
        quat_tol: float = 1e-3,
        cache_dir: str | os.PathLike[str] | None = None,
    ) -> None:
        if stamp not in ("header", "log") or on_bad not in ("skip", "error"):
            raise ValueError(f"stamp={stamp!r}, on_bad={on_bad!r}: expected header|log, skip|error")
        corner_permutation(corner_order)  # validates (TagInputError)
        if default_family is not None:
            family_spec(default_family)  # validates (TagBackendError)
        self.path = Path(path)
        self._file = open_bag(self.path, cache_dir)
        self._opts = validate(
            DecodeOptions,
            {"stamp": stamp, "corner_order": corner_order, "pixel_offset": pixel_offset,
             "default_family": default_family, "quat_tol": quat_tol},
            "bag reader options",
        )  # fmt: skip
        self._on_bad = on_bad
        self.skipped: dict[str, int] = {}
        self._warned: set[tuple[str, str]] = set()
        with self._reader() as reader:
            self.bag_topics = {
                name: BagTopic(info.msgtype or "(several types)", info.msgcount)
                for name, info in reader.topics.items()
            }
            empty = not reader.message_count
            self.start_ns = 0 if empty else int(reader.start_time)
            self.end_ns = 0 if empty else int(reader.end_time)
        self._selected = self._select(topics)

    @property
    def topics(self) -> dict[str, type[Message]]:
        """Stream topic -> record type, for the topics this source yields."""
        return {sel.name: sel.record for sel in self._selected.values()}

    def __iter__(self) -> Iterator[tuple[str, Message]]:
        """Yield ``(topic, record)`` in log-time order; starts over on each call."""
        return self._stream()

    # ----- internals ------------------------------------------------------------------------------
    def _describe(self) -> str:
        kind = "a ROS 2 bag" if self._file.is_dir() else BAG_KINDS.get(self._file.suffix, "a bag")
        return f"{self.path}: cannot open as {kind}"

    def _reader(self) -> Any:
        """An opened ``AnyReader`` (a context manager), errors mapped to BagFormatError."""
        from rosbags.highlevel import AnyReader

        try:
            reader = AnyReader([self._file], default_typestore=make_typestore(2))
            reader.open()
        except Exception as exc:  # third-party parsing of an untrusted file: map every failure
            raise BagFormatError(f"{self._describe()} ({_one_line(exc)})") from exc
        return contextlib.closing(reader)

    def _select(self, topics: Mapping[str, str] | Sequence[str] | None) -> dict[str, _Selected]:
        listing = ", ".join(f"{n} ({t.msgtype}, {t.msgcount})" for n, t in self.bag_topics.items())
        if topics is None:
            wanted = {n: n for n, t in self.bag_topics.items() if t.msgtype in DECODERS}
            if ignored := sorted(set(self.bag_topics) - set(wanted)):
                logger.info("%s: not reading topics of unsupported types: %s", self.path, ignored)
            if not wanted:
                raise BagTopicError(f"{self.path}: no topic of a type tagloc reads; has {listing}")
        elif isinstance(topics, Mapping):
            wanted = {str(k): str(v) for k, v in topics.items()}
        else:
            wanted = {t: t for t in ([topics] if isinstance(topics, str) else map(str, topics))}
        if len(set(wanted.values())) != len(wanted):
            raise BagTopicError(f"topics: two bag topics renamed to the same name: {wanted}")
        selected: dict[str, _Selected] = {}
        for name, out in wanted.items():
            if name not in self.bag_topics:
                raise BagTopicError(f"{self.path}: no topic {name!r}; the bag has {listing}")
            msgtype = self.bag_topics[name].msgtype
            if msgtype not in DECODERS:
                raise BagFormatError(
                    f"{self.path}: topic {name!r} has type {msgtype}, which tagloc does not read "
                    f"(supported: {', '.join(DECODERS)})"
                )
            static = name.rstrip("/").rsplit("/", 1)[-1] == "tf_static"
            selected[name] = _Selected(out, DECODERS[msgtype][1], static)
        return selected

    def _stream(self) -> Iterator[tuple[str, Message]]:
        self.skipped, self._warned = {}, set()
        last: dict[tuple[str, str], int] = {}
        counts = dict.fromkeys(self._selected, 0)
        with self._reader() as reader:
            conns = [c for c in reader.connections if c.topic in self._selected]
            for conn, log_ns, raw in self._raw(reader, conns):
                topic = conn.topic
                sel, index = self._selected[topic], counts[topic]
                counts[topic] = index + 1
                for item in self._decode(reader, conn.msgtype, raw, log_ns, sel, topic, index):
                    if isinstance(item, Bad):
                        self._bad(topic, index, item)
                    elif not sel.static and (bad := _order(item, topic, last)) is not None:
                        self._bad(topic, index, bad)
                    else:
                        yield sel.name, item
        if self.skipped:
            logger.warning("%s: skipped %s", self.path, self.skipped)

    def _raw(self, reader: Any, conns: list[Any]) -> Iterator[tuple[Any, int, bytes]]:
        messages = reader.messages(connections=conns)
        while True:
            try:
                item = next(messages)
            except StopIteration:
                return
            except Exception as exc:  # damaged data inside the file (rosbags, sqlite, codecs)
                raise BagFormatError(
                    f"{self.path}: damaged data, reading stopped ({_one_line(exc)})"
                ) from exc
            yield item

    def _decode(
        self, reader: Any, msgtype: str, raw: bytes, log_ns: int, sel: _Selected, topic: str,
        index: int,
    ) -> list[Message | Bad]:  # fmt: skip
        try:
            msg = reader.deserialize(raw, msgtype)
        except Exception as exc:  # a message whose bytes do not fit its type
            return [Bad("undecodable", _one_line(exc))]
        try:
            return decode(msgtype, msg, log_ns, self._opts, sel.static)
        except RecordError as exc:
            return [Bad("invalid_record", str(exc))]
        except BagFormatError as exc:
            raise BagFormatError(f"{self.path}: {topic} message {index}: {exc}") from None

    def _bad(self, topic: str, index: int, bad: Bad) -> None:
        where = f"{self.path}: {topic} message {index}"
        if self._on_bad == "error":
            raise BagFormatError(f"{where}: {bad.reason}: {bad.detail}")
        self.skipped[bad.reason] = self.skipped.get(bad.reason, 0) + 1
        if (topic, bad.reason) not in self._warned:
            self._warned.add((topic, bad.reason))
            logger.warning("%s: skipped (%s): %s; further ones are counted", where, *bad)


def _order(item: Message, topic: str, last: dict[tuple[str, str], int]) -> Bad | None:
    """Check that ``item.stamp_ns`` increases strictly on its topic (and child frame)."""
    key = (topic, item.child if isinstance(item, TransformMsg) else "")
    previous = last.get(key)
    if previous is not None and item.stamp_ns <= previous:
        reason = "duplicate_stamp" if item.stamp_ns == previous else "stamp_backwards"
        return Bad(reason, f"stamp {item.stamp_ns} ns after {previous} ns")
    last[key] = item.stamp_ns
    return None


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 300 else text[:297] + "..."
