"""The one driver of the streaming node: a message source through a node, on a clock.

:func:`run` builds the node with the sinks (its outputs go nowhere else, and the list is never
edited), feeds it the source's ``(topic, record)`` pairs and finishes it:

- ``clock="replay"``: as fast as possible, every record fed in arrival order on this thread
  (evaluation, the scenarios, the benchmarks, ``tagloc localize`` on a bag);
- ``clock="wall"``: paced by the wall clock at ``speed``, images detected on a worker thread
  behind a drop-oldest queue (:mod:`tagloc.localize.realtime`; ``tagloc localize --realtime``);
  the result carries the latencies measured (:class:`~tagloc.localize.realtime_stats.
  RealtimeStats`).

The node is given as a function of its sinks (``functools.partial(LocalizerNode, tag_map,
config, premap=...)``), so the driver can add the sink it measures with before the node exists.
:func:`record_run` is :func:`run` with a :class:`~tagloc.localize.outputs.RunRecorder` among the
sinks, returning the :class:`~tagloc.localize.run.LocalizationRun` evaluation scores.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

from tagloc.localize.fix import LocalizeError
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import OutputSink, RunRecorder
from tagloc.localize.realtime_stats import RealtimeStats
from tagloc.localize.run import LocalizationRun
from tagloc.messages import Message
from tagloc.tags import TagDetector

__all__ = ["Clock", "NodeFactory", "RunResult", "StreamInputError", "record_run", "run"]

#: How the driver paces the stream.
Clock = Literal["replay", "wall"]
#: Builds the node with the given sinks (e.g. ``functools.partial(LocalizerNode, tag_map, cfg)``).
NodeFactory = Callable[[Sequence[OutputSink]], LocalizerNode]


class StreamInputError(LocalizeError):
    """A stream the node cannot localize from (the message names topic and problem)."""


@dataclass(frozen=True, slots=True)
class RunResult:
    """What one :func:`run` leaves besides the outputs in the sinks.

    Attributes
    ----------
    node : LocalizerNode
        The finished node (its :meth:`~LocalizerNode.metadata`, skips, extrinsics).
    node_s : float
        Wall time spent in the node (``replay``: its ``feed`` and ``finish`` calls; ``wall``: the
        whole run), s.
    realtime : RealtimeStats or None
        ``clock="wall"``: frames, drops and latencies; None for ``replay``.
    """

    node: LocalizerNode
    node_s: float
    realtime: RealtimeStats | None = None


def run(
    node: NodeFactory, source: Iterable[tuple[str, Message]], sinks: Sequence[OutputSink] = (),
    *, clock: Clock = "replay", speed: float | None = 1.0, queue_size: int = 2,
    detector: TagDetector | None = None, worker_nice: int = 10,
) -> RunResult:  # fmt: skip
    """Run the node built by ``node(sinks)`` on ``source`` (module docstring).

    Parameters
    ----------
    node : callable
        ``node(sinks) -> LocalizerNode``.
    source : iterable of (topic, Message)
        In arrival order; a :class:`~tagloc.messages.MessageSource` names its topics up front,
        and a stream without the node's odometry topic is refused before any record is read.
    sinks : sequence of OutputSink
        Every output of the node, as it happens.
    clock : {"replay", "wall"}
    speed, queue_size, detector, worker_nice
        ``wall`` only: see :func:`tagloc.localize.realtime.run_wall`.

    Raises
    ------
    StreamInputError
        If the source lacks the odometry topic or held no usable odometry.
    ValueError
        For an unknown ``clock`` (or a bad ``speed`` / ``queue_size`` with ``wall``).
    """
    if clock == "wall":
        from tagloc.localize.realtime import run_wall

        start = time.perf_counter()
        built, stats = run_wall(
            node, source, sinks, speed=speed, queue_size=queue_size, detector=detector,
            worker_nice=worker_nice, check=_check_topics,
        )  # fmt: skip
        return RunResult(built, time.perf_counter() - start, stats)
    if clock != "replay":
        raise ValueError(f"clock: expected 'replay' or 'wall', got {clock!r}")
    built = node(tuple(sinks))
    _check_topics(built, source)
    spent = 0.0
    for topic, msg in source:
        t0 = time.perf_counter()
        built.feed(topic, msg)
        spent += time.perf_counter() - t0
    t0 = time.perf_counter()
    finish(built)
    return RunResult(built, spent + time.perf_counter() - t0)


def finish(node: LocalizerNode) -> None:
    """``node.finish()``, its "no odometry" error as a :class:`StreamInputError`."""
    try:
        node.finish()
    except LocalizeError as exc:
        raise StreamInputError(str(exc)) from None


def record_run(
    node: NodeFactory, source: Iterable[tuple[str, Message]], *, name: str = "run",
    sinks: Sequence[OutputSink] = (), clock: Clock = "replay",
) -> LocalizationRun:  # fmt: skip
    """:func:`run` with a :class:`RunRecorder` (first among ``sinks``): the recorded run, its
    ``metadata`` the node's plus ``node_wall_s``."""
    recorder = RunRecorder(name)
    result = run(node, source, [recorder, *sinks], clock=clock)
    metadata = result.node.metadata()
    metadata["node_wall_s"] = result.node_s
    return recorder.run(metadata)


def _check_topics(node: LocalizerNode, source: Iterable[tuple[str, Message]]) -> None:
    topics = getattr(source, "topics", None)  # a MessageSource names its topics up front
    t = node.topics
    if isinstance(topics, Mapping) and not {t.odom, t.tf} & set(topics):
        raise StreamInputError(
            f"odometry topic {t.odom!r} is not in the input (topics: "
            f"{', '.join(sorted(topics)) or 'none'})"
        )
