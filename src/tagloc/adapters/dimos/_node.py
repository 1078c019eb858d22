"""The one place the dimos module meets tagloc's streaming node (no dimos import here).

:class:`LiveNode` builds a :class:`~tagloc.localize.node.LocalizerNode` with a sink that hands
each :class:`~tagloc.localize.outputs.Estimate` and :class:`~tagloc.supervise.StatusReport` to
callbacks, and feeds it records through :meth:`LiveNode.feed`, under one lock: dimos delivers
each input stream on its own thread, the node is single-threaded.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

import numpy as np

from tagloc.localize.config import LocalizerConfig, load_localizer_config
from tagloc.localize.config_tags import FramesConfig
from tagloc.localize.node import LocalizerNode
from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.messages import CameraInfoMsg, ImageMsg, Message, PointCloudMsg, TransformMsg
from tagloc.supervise import StatusReport
from tagloc.tags import TagMap

__all__ = ["LiveNode", "live_config"]


def live_config(
    path: str | Path | None, map_frame: str, odom_frame: str, base_frame: str
) -> LocalizerConfig:
    """``localizer.yaml`` (defaults without one) with the module's frame names (the odometry
    origin is dimos's ``world_frame``; the published edge ``odom_to_map``, as dimos's
    relocalization publishes) and live order (``output.publish_first``: each odometry sample's
    correction before the frames it completes, as ``tagloc localize --realtime``).

    Raises
    ------
    ConfigError
        From :func:`~tagloc.localize.load_localizer_config` (one line naming the field).
    """
    config = LocalizerConfig() if path is None else load_localizer_config(path)
    frames = FramesConfig(convention="dimos", map_frame=map_frame, odom_frame=odom_frame,
                          base_frame=base_frame, publish="odom_to_map")  # fmt: skip
    output = config.output.model_copy(update={"publish_first": True})
    return config.model_copy(update={"frames": frames, "output": output})


class _Callbacks:
    """The node's sink: estimates and status reports to the module."""

    def __init__(
        self, on_estimate: Callable[[Estimate], None], on_status: Callable[[StatusReport], None]
    ) -> None:
        self.on_estimate, self.on_status = on_estimate, on_status

    def write(self, output: NodeOutput) -> None:
        if isinstance(output, Estimate):
            self.on_estimate(output)
        elif isinstance(output, StatusReport):
            self.on_status(output)


class LiveNode:
    """A :class:`LocalizerNode` fed from several threads (module docstring).

    Parameters
    ----------
    tag_map, config
        As for :class:`LocalizerNode` (``config`` from :func:`live_config`).
    premap : (N, 3) float, optional
        The lidar premap in the map frame (None: no lidar fixes).
    on_estimate, on_status
        Called (with the lock held, on the feeding thread) with every estimate and status.

    Raises
    ------
    LocalizeError
        From :class:`LocalizerNode` (a premap that misses the tag map).
    """

    def __init__(
        self, tag_map: TagMap, config: LocalizerConfig, premap: np.ndarray | None,
        on_estimate: Callable[[Estimate], None], on_status: Callable[[StatusReport], None],
    ) -> None:  # fmt: skip
        sink = _Callbacks(on_estimate, on_status)
        self._node = LocalizerNode(tag_map, config, [sink], premap=premap)
        self.lock = threading.RLock()

    def feed(self, msg: Message) -> None:
        """One record, on the node topic of its kind (odometry as a ``TransformMsg`` of the
        configured ``odom -> base`` edge; a static ``TransformMsg`` for a mounting)."""
        t = self._node.topics
        if isinstance(msg, ImageMsg):
            topic = t.image
        elif isinstance(msg, CameraInfoMsg):
            topic = t.camera_info
        elif isinstance(msg, PointCloudMsg):
            topic = t.lidar
        elif isinstance(msg, TransformMsg):
            topic = t.tf
        else:
            raise TypeError(f"LiveNode.feed: no role for {type(msg).__name__}")
        with self.lock:
            self._node.feed(topic, msg)

    @property
    def skipped(self) -> dict[str, int]:
        """Inputs the node skipped, by reason (each reason logged once by the node)."""
        return dict(self._node.skipped)

    @property
    def has_camera(self) -> bool:
        """Whether the node has its camera model."""
        return self._node.camera is not None
