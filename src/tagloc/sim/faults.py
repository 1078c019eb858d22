"""Stream-level faults: what goes wrong between the sensors and the node, applied to a stream.

A fault rewrites the ``(topic, record)`` stream of a source (:class:`~tagloc.sim.scenarios.
ScenarioSource`) the way a bag or a live robot would deliver it after the failure: messages
lost, sent twice, or stamped by a clock that jumped. The node sees them exactly as from a bag.
Faults are pure data (:class:`DropMessages`, :class:`DuplicateMessages`, :class:`ClockJump`);
:func:`apply_faults` chains them. Times are seconds after ``t0_ns`` (the stream's first stamp)
and a message belongs to a window by its own (original) stamp.

The fault scenarios of :data:`~tagloc.sim.scenarios.SCENARIOS`, the ladder walk each must
produce, and the walk measured (seed 0, the first 60 s of the office route; the tests are in
``tests/localize/test_faults.py``). The node starts at level 4 and reaches level 3
(``markers_alone``: the node does not use the simulator's lidar yet) at its first fix, 6.20 s
in. Lidar point clouds (:class:`~tagloc.messages.PointCloudMsg`) are records like any other: a
fault with no ``kinds`` hits them too, and ``lidar_unplugged`` drops them alone.

===================  ============================================================================
camera_unplugged     no ``TagDetectionsMsg`` from 30 s to 50 s (tags in view before and after).
                     Expected: 3 -> 4 at the first odometry sample past the camera's
                     ``supervisor.camera.timeout_s`` (1 s) after the last frame (``markers:
                     camera dead``); 4 -> 3 once frames are back and the filter accepts again
                     (20 s is a gap: ``gates.k_consistent`` consistent fixes first).
                     Measured: 3 -> 4 at 31.00 s, 4 -> 3 at 50.10 s (frames back at 50.03 s).
odometry_stall       no ``OdometryMsg`` from 40 s to 42 s; camera frames continue. Expected:
                     3 -> 4 (``odometry dead``) after ``supervisor.odometry.timeout_s`` (0.5 s;
                     the supervisor also steps at camera frames, so the silence is seen while
                     frames arrive), back to 3 when odometry returns; nothing skipped; the fused
                     error after the stall that of the clean drive. Measured: 3 -> 4 at 40.50 s,
                     4 -> 3 at 42.00 s; every frame of the stall used once odometry is back,
                     error as clean from 45 s on.
clock_jump_back      from 45 s on, odometry stamps are 5 s earlier (a restarted clock; frames
                     keep the camera's clock). Expected: the node starts over (as ROS tf clears
                     its buffer on a jump back: buffer, estimate and waiting frames dropped) and
                     the ladder falls to 4 at once, its reason the jump. Measured: 3 -> 4 at the
                     first odometry stamp after the jump (40.00 s) with "clock jumped back
                     4.990 s"; the camera then runs 5 s ahead of the odometry, which the
                     supervisor sees as silent odometry at every frame: 4 while that lasts.
duplicated_messages  every message from 30 s to 40 s sent twice (100 lidar sweeps among them,
                     which the node ignores). Expected and measured: 1000
                     ``odom_duplicate_stamp`` and 300 ``frame_duplicate_stamp`` skips; the walk
                     (3 at 6.20 s, no other move) and the fused trajectory bit-identical to the
                     drive without duplicates.
===================  ============================================================================
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Protocol

from tagloc.messages import Message
from tagloc.units import S_NS

__all__ = ["ClockJump", "DropMessages", "DuplicateMessages", "StreamFault", "apply_faults"]

logger = logging.getLogger(__name__)
Stream = Iterable[tuple[str, Message]]


class StreamFault(Protocol):
    """A rewrite of a message stream (a fault between the sensors and the node)."""

    def apply(self, stream: Stream, t0_ns: int) -> Iterator[tuple[str, Message]]:
        """The stream as delivered with the fault; ``t0_ns``: the time origin of the fault's
        times (the stream's first stamp)."""
        ...

    def describe(self) -> str:
        """One line for a run's metadata."""
        ...


def _matches(msg: Message, kinds: tuple[type[Message], ...]) -> bool:
    return not kinds or isinstance(msg, kinds)


def _kind_names(kinds: tuple[type[Message], ...]) -> str:
    return ", ".join(k.__name__ for k in kinds) or "every message"


@dataclass(frozen=True, slots=True)
class _WindowFault:
    """A fault on the messages of ``kinds`` (empty: every record) stamped in
    ``[start_s, end_s)``, seconds after ``t0_ns``."""

    start_s: float
    end_s: float
    kinds: tuple[type[Message], ...] = ()

    def describe(self) -> str:
        raise NotImplementedError

    def _windowed(self, stream: Stream, t0_ns: int) -> Iterator[tuple[str, Message, bool]]:
        """Each message and whether the window and kinds hit it (the fault logged once)."""
        lo, hi = t0_ns + round(self.start_s * S_NS), t0_ns + round(self.end_s * S_NS)
        logged = False
        for topic, msg in stream:
            hit = lo <= msg.stamp_ns < hi and _matches(msg, self.kinds)
            if hit and not logged:
                logger.info("fault: %s", self.describe())
                logged = True
            yield topic, msg, hit


@dataclass(frozen=True, slots=True)
class DropMessages(_WindowFault):
    """Messages of ``kinds`` (record types; empty: every record) stamped in the silence
    ``[start_s, end_s)``, seconds after ``t0_ns``, are lost (a sensor unplugged, a driver
    stalled)."""

    def apply(self, stream: Stream, t0_ns: int) -> Iterator[tuple[str, Message]]:
        for topic, msg, hit in self._windowed(stream, t0_ns):
            if not hit:
                yield topic, msg

    def describe(self) -> str:
        return f"{_kind_names(self.kinds)} dropped from {self.start_s:g} s to {self.end_s:g} s"


@dataclass(frozen=True, slots=True)
class DuplicateMessages(_WindowFault):
    """Every message of ``kinds`` stamped in ``[start_s, end_s)`` (as in :class:`DropMessages`)
    is delivered twice in a row (a publisher started twice, a bag merged with itself)."""

    def apply(self, stream: Stream, t0_ns: int) -> Iterator[tuple[str, Message]]:
        for topic, msg, hit in self._windowed(stream, t0_ns):
            yield topic, msg
            if hit:
                yield topic, msg

    def describe(self) -> str:
        return f"{_kind_names(self.kinds)} sent twice from {self.start_s:g} s to {self.end_s:g} s"


@dataclass(frozen=True, slots=True)
class ClockJump:
    """From ``at_s`` on, messages of ``kinds`` are stamped ``back_s`` earlier: their clock
    jumped back once and runs on from the jumped value (a restarted clock). Delivery order is
    unchanged (the stream's order is arrival order).

    Attributes
    ----------
    at_s : float
        The jump, seconds after ``t0_ns`` (by the original stamps).
    back_s : float
        How far back, s (> 0).
    kinds : tuple of type
        Record types on the jumping clock (empty: every record).

    Raises
    ------
    ValueError
        If ``back_s`` is not positive.
    """

    at_s: float
    back_s: float
    kinds: tuple[type[Message], ...] = ()

    def __post_init__(self) -> None:
        if not self.back_s > 0:
            raise ValueError(f"ClockJump.back_s: must be > 0, got {self.back_s}")

    def apply(self, stream: Stream, t0_ns: int) -> Iterator[tuple[str, Message]]:
        at, back = t0_ns + round(self.at_s * S_NS), round(self.back_s * S_NS)
        logged = False
        for topic, msg in stream:
            if msg.stamp_ns >= at and _matches(msg, self.kinds):
                if not logged:
                    logger.info("fault: %s", self.describe())
                    logged = True
                msg = dataclasses.replace(msg, stamp_ns=max(msg.stamp_ns - back, 0))
            yield topic, msg

    def describe(self) -> str:
        return f"{_kind_names(self.kinds)} clock jumps {self.back_s:g} s back at {self.at_s:g} s"


def apply_faults(
    stream: Stream, faults: Sequence[StreamFault], t0_ns: int
) -> Iterator[tuple[str, Message]]:
    """``stream`` with each of ``faults`` applied, in order (lazily: nothing is buffered).

    Parameters
    ----------
    stream : iterable of (str, Message)
        ``(topic, record)`` pairs in arrival order.
    faults : sequence of StreamFault
    t0_ns : int
        Origin of the faults' times, ns (the stream's first stamp).
    """
    out: Iterable[tuple[str, Message]] = stream
    for fault in faults:
        out = fault.apply(out, t0_ns)
    return iter(out)
