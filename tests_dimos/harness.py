"""Feeding tagloc records into a module through real dimos transports, and the offline oracle.

Each stream of the module gets its own LCM transport on the in-memory provider (``memq://``): a
message published on it is LCM-encoded, queued, decoded and delivered on the transport's own
thread, as between two modules. :func:`publish_all` sends one record at a time and waits until
the module has handled it (its ``status()["received"]`` count), so that the module sees the
records in the order the offline node does.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from dimos.core.transport import LCMTransport
from dimos.msgs.tf2_msgs.TFMessage import TFMessage

from tagloc.adapters.dimos import convert
from tagloc.adapters.dimos._node import live_config
from tagloc.io.dimos_premap import read_pc2_lcm
from tagloc.localize.node import LocalizerNode, NodeTopics
from tagloc.localize.outputs import Estimate, NodeOutput
from tagloc.messages import CameraInfoMsg, ImageMsg, Message, PointCloudMsg, TransformMsg
from tagloc.tags import load_tag_map


def wire(module: Any, names: Iterable[str]) -> dict[str, LCMTransport]:
    """In-memory LCM transports for the module's streams ``names`` (each its own topic)."""
    transports = {}
    for name in names:
        stream = getattr(module, name)
        transport = LCMTransport(f"/test/{name}", stream.type, url="memq://")
        module.set_transport(name, transport)
        transports[name] = transport
    return transports


def to_dimos(record: Message) -> tuple[str, Any]:
    """The stream and the dimos message of a record (static mounts as plain tf edges)."""
    if isinstance(record, TransformMsg):
        edge = convert.transform(record.T_parent_child, record.parent, record.child,
                                 convert.stamp_s(record.stamp_ns))  # fmt: skip
        return "tf", TFMessage(edge)
    if isinstance(record, ImageMsg):
        return "color_image", convert.dimos_image(record)
    if isinstance(record, CameraInfoMsg):
        return "camera_info", convert.camera_info(record)
    if isinstance(record, PointCloudMsg):
        return "lidar", convert.point_cloud(record)
    raise TypeError(type(record).__name__)


def decoded(record: Message) -> Message:
    """The record as the module receives it: to dimos, LCM-encoded and decoded, and back."""
    name, msg = to_dimos(record)
    msg = type(msg).lcm_decode(msg.lcm_encode())
    if name == "tf":
        (edge,) = msg.transforms
        static = isinstance(record, TransformMsg) and record.static
        return convert.transform_msg(edge, static=static)
    if name == "color_image":
        return convert.image_msg(msg)
    if name == "camera_info":
        return convert.camera_info_msg(msg)
    return convert.point_cloud_msg(msg)


def publish_all(
    module: Any, transports: dict[str, LCMTransport], records: Iterable[Message],
    timeout_s: float = 30.0,
) -> None:  # fmt: skip
    """Publish each record and wait until the module has handled it."""
    for record in records:
        name, msg = to_dimos(record)
        before = module.status()["received"].get(name, 0)
        transports[name].publish(msg)
        deadline = time.monotonic() + timeout_s
        while module.status()["received"].get(name, 0) <= before:
            if time.monotonic() > deadline:
                raise TimeoutError(f"the module did not handle a {name} message")
            time.sleep(0.0002)


class _Estimates:
    def __init__(self) -> None:
        self.published: list[Estimate] = []

    def write(self, output: NodeOutput) -> None:
        if isinstance(output, Estimate) and output.initialized and output.publish:
            self.published.append(output)


def offline(
    tags: Path, records: Iterable[Message], config: Path, premap: Path, odom_frame: str
) -> list[Estimate]:
    """The offline node on the same records and files: its published estimates, in order."""
    sink = _Estimates()
    cfg = live_config(config, "map", odom_frame, "base_link")
    node = LocalizerNode(load_tag_map(tags), cfg, [sink], premap=read_pc2_lcm(premap))
    topics = NodeTopics()
    for record in records:
        topic = {ImageMsg: topics.image, CameraInfoMsg: topics.camera_info,
                 PointCloudMsg: topics.lidar}.get(type(record), topics.tf)  # fmt: skip
        node.feed(topic, record)
    return sink.published
