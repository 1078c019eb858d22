"""A whole stream through the node into a :class:`LocalizationRun` (for evaluation and tests).

:class:`LocalizationPipeline` is the streaming node (:class:`~tagloc.localize.node.
LocalizerNode`) with a :class:`~tagloc.localize.outputs.RunRecorder` among its sinks: the same
code path as a live robot or ``tagloc localize``, with the run assembled by the recorder.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from tagloc.camera import CameraModel
from tagloc.geometry import SE3
from tagloc.localize.config import LocalizerConfig
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import LocalizeError
from tagloc.localize.node import FrameTruth, LocalizerNode, NodeTopics
from tagloc.localize.outputs import OutputSink, RunRecorder
from tagloc.localize.run import LocalizationRun
from tagloc.messages import Message
from tagloc.tags import TagDetector, TagMap

__all__ = ["FrameTruth", "LocalizationPipeline", "PipelineInputError", "PipelineTopics", "localize"]

#: The node's topic roles (the name this module has always used).
PipelineTopics = NodeTopics


class PipelineInputError(LocalizeError):
    """A stream the node cannot localize from (the message names topic and problem)."""


class LocalizationPipeline:
    """Feed it ``(topic, record)`` pairs in arrival order; :meth:`finish` returns the run.

    Parameters are the node's (:class:`LocalizerNode`), plus ``name`` (of the run) and extra
    ``sinks`` that receive the outputs as they happen beside the recorder.
    """

    def __init__(
        self, tag_map: TagMap, config: LocalizerConfig | None = None, *,
        camera: CameraModel | None = None, T_base_cam: SE3 | None = None,
        topics: NodeTopics | None = None, detector: TagDetector | None = None,
        frame_truth: Mapping[int, FrameTruth] | None = None, name: str = "run",
        sinks: Sequence[OutputSink] = (), premap: np.ndarray | None = None,
    ) -> None:  # fmt: skip
        self.recorder = RunRecorder(name)
        self.node = LocalizerNode(
            tag_map, config, [self.recorder, *sinks], camera=camera, T_base_cam=T_base_cam,
            topics=topics, detector=detector, frame_truth=frame_truth, premap=premap,
        )  # fmt: skip
        self.config, self.topics = self.node.config, self.node.topics
        self.name = name
        self._wall_s = 0.0

    @property
    def filter(self) -> MapOdomFilter:
        """The node's filter (a new one after a clock jump)."""
        return self.node.filter

    @property
    def skipped(self) -> dict[str, int]:
        return dict(self.node.skipped)

    def feed(self, topic: str, msg: Message) -> None:
        """Consume one stream item."""
        t0 = time.perf_counter()
        self.node.feed(topic, msg)
        self._wall_s += time.perf_counter() - t0

    def run(self, stream: Iterable[tuple[str, Message]]) -> LocalizationRun:
        """Feed a whole stream and :meth:`finish`. Checks ``stream.topics`` when it has them."""
        topics = getattr(stream, "topics", None)  # a MessageSource names its topics up front
        if isinstance(topics, Mapping) and not {self.topics.odom, self.topics.tf} & set(topics):
            raise PipelineInputError(
                f"odometry topic {self.topics.odom!r} is not in the input (topics: "
                f"{', '.join(sorted(topics)) or 'none'})"
            )
        for topic, msg in stream:
            self.feed(topic, msg)
        return self.finish()

    def finish(self) -> LocalizationRun:
        """Process frames still held and return the recorded run.

        Raises
        ------
        PipelineInputError
            If the stream held no usable odometry.
        """
        try:
            self.node.finish()
        except LocalizeError as exc:
            raise PipelineInputError(str(exc)) from None
        metadata = self.node.metadata()
        metadata["pipeline_wall_s"] = self._wall_s
        return self.recorder.run(metadata)


def localize(
    stream: Iterable[tuple[str, Message]], tag_map: TagMap, config: LocalizerConfig | None = None,
    **options: Any,
) -> LocalizationRun:  # fmt: skip
    """Localize a whole stream: ``LocalizationPipeline(tag_map, config, **options).run(stream)``."""
    return LocalizationPipeline(tag_map, config, **options).run(stream)
