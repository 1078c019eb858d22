"""The options that say how to read a bag: its camera (``--cameras`` ...) and its topics.

A command that reads a bag takes one parameter ``bag_inputs: BagInputs`` where these options
belong and is decorated with :func:`with_bag_inputs`, which puts the options there on the command
line (the same names, help and defaults in every command) and hands the command their values as
one :class:`BagInputs`::

    @app.command("bag")
    @with_bag_inputs
    def eval_bag(bag: ..., bag_inputs: BagInputs, jobs: JobsOpt = 1) -> None: ...
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable, Collection
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tagloc.cli import bag_camera as opts
from tagloc.cli.bag_camera import BagCamera

if TYPE_CHECKING:
    from tagloc.messages import NodeTopics

__all__ = ["DEFAULT_BAG_INPUTS", "BagInputs", "bag_topics_to_read", "with_bag_inputs"]

#: The options in their command-line order: (parameter name, annotated type, default).
_CAMERA_OPTIONS: tuple[tuple[str, Any, Any], ...] = (
    ("cameras", opts.CamerasOpt, None),
    ("camera_poses", opts.CameraPosesOpt, None),
    ("tagslam", opts.TagslamOpt, None),
    ("corner_order", opts.CornerOrderOpt, "tl_tr_br_bl"),
)
_TOPIC_OPTIONS: tuple[tuple[str, Any, Any], ...] = (
    ("odom_topic", opts.OdomTopicOpt, "/odom"),
    ("detections_topic", opts.DetectionsTopicOpt, "/tag_detections"),
    ("image_topic", opts.ImageTopicOpt, "/camera/image"),
    ("camera_info_topic", opts.CameraInfoTopicOpt, "/camera/camera_info"),
    ("tf_topic", opts.TfTopicOpt, "/tf"),
)


@dataclass(frozen=True, slots=True)
class BagInputs:
    """What the bag options gave: the camera description and the topic of each role."""

    camera: BagCamera
    odom_topic: str = "/odom"
    detections_topic: str = "/tag_detections"
    image_topic: str = "/camera/image"
    camera_info_topic: str = "/camera/camera_info"
    tf_topic: str = "/tf"

    def topics(self, truth: str = "/ground_truth") -> NodeTopics:
        """The node's topics (``truth``: the ground-truth topic, which has no option here)."""
        from tagloc.messages import NodeTopics

        return NodeTopics(self.odom_topic, self.detections_topic, self.image_topic,
                          self.camera_info_topic, truth, self.tf_topic)  # fmt: skip


#: The default of a command's ``bag_inputs`` parameter (the options' defaults).
DEFAULT_BAG_INPUTS = BagInputs(BagCamera())


def with_bag_inputs(command: Callable[..., Any]) -> Callable[..., Any]:
    """Put the bag options where ``command`` has its ``bag_inputs`` parameter; call it with
    their values as one :class:`BagInputs`."""
    signature = inspect.signature(command, eval_str=True)
    options = [
        inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY, annotation=kind, default=default)
        for name, kind, default in (*_CAMERA_OPTIONS, *_TOPIC_OPTIONS)
    ]
    params: list[inspect.Parameter] = []
    for param in signature.parameters.values():
        params += options if param.name == "bag_inputs" else [param.replace(kind=options[0].kind)]

    @functools.wraps(command)
    def run(**kwargs: Any) -> Any:
        camera = BagCamera(*(kwargs.pop(name) for name, _, _ in _CAMERA_OPTIONS))
        topics = {name: kwargs.pop(name) for name, _, _ in _TOPIC_OPTIONS}
        return command(**kwargs, bag_inputs=BagInputs(camera, **topics))

    run.__signature__ = signature.replace(parameters=params)  # type: ignore[attr-defined]
    run.__annotations__ = {p.name: p.annotation for p in params}
    return run


def bag_topics_to_read(
    bag: Path, topics: NodeTopics, corner_order: str, family: str, *, truth: bool = True,
    rig_topics: Collection[str] = (),
) -> list[str]:  # fmt: skip
    """The node's topics present in ``bag`` (with every ``tf_static``; the ground truth unless
    ``truth`` is false; the tag topics of a rig's cameras, ``rig_topics``); one line if it has no
    odometry or no camera frames."""
    from tagloc.io import BagSource
    from tagloc.localize import LocalizeError

    present = BagSource(bag, corner_order=corner_order, default_family=family).bag_topics
    names = ", ".join(sorted(present)) or "none"
    if topics.odom not in present and topics.tf not in present:
        raise LocalizeError(f"{bag}: no odometry: neither {topics.odom!r} nor {topics.tf!r} is in "
                            f"the bag (topics: {names})")  # fmt: skip
    rig = [t for t in rig_topics if t in present]
    if not rig and topics.detections not in present and topics.image not in present:
        raise LocalizeError(f"{bag}: no camera frames: neither {topics.detections!r} nor "
                            f"{topics.image!r} is in the bag (topics: {names})")  # fmt: skip
    roles = (topics.odom, topics.detections, topics.image, topics.camera_info, topics.tf)
    wanted = [t for t in (*roles, *((topics.truth,) if truth else ()), *rig) if t in present]
    wanted += [t for t in present if t.rstrip("/").endswith("tf_static")]
    return sorted(set(wanted))
