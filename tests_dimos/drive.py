"""A short simulated drive as tagloc stream records, with rendered camera images.

The simulator's stream (:class:`~tagloc.sim.scenarios.ScenarioSource`) with each frame's
detections replaced by the frame's rendered image (:func:`~tagloc.sim.render.render_frames`) and
the odometry as ``odom -> base_link`` transforms (what dimos's ``tf`` carries), so that the node
detects the tags itself, as it does on a robot.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cache

import numpy as np

from tagloc.eval.scenarios import calibrated_config, scenario_config
from tagloc.geometry import SE3
from tagloc.messages import (
    CameraInfoMsg,
    GroundTruthMsg,
    ImageMsg,
    Message,
    OdometryMsg,
    PointCloudMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.sim.render import render_frames
from tagloc.sim.scenarios import ScenarioSource, build_scenario, scenario_premap
from tagloc.tags import TagMap

#: Seconds of the drive the tests use (the default scenario: the office route).
DURATION_S = 30.0
#: Every this many camera frames is kept (30 Hz -> 10 Hz, a live robot's detection rate).
FRAME_STEP = 3
#: The drive's clock starts here (near today's epoch, as a robot's clock), ns.
T0_NS = 1_700_000_000 * 10**9


@dataclass(frozen=True)
class Drive:
    """The records in arrival order, the tag map, the premap and a configuration."""

    records: tuple[Message, ...]
    #: The true ``T_map_base`` at each odometry stamp (simulator ground truth).
    truth: dict[int, SE3]
    tag_map: TagMap
    premap: np.ndarray
    config_yaml: str

    def of_type(self, kind: type) -> list[Message]:
        return [r for r in self.records if isinstance(r, kind)]


def _stamp(stamp: int) -> int:
    """On the robot's clock, to the microsecond (what a dimos stamp carries)."""
    return T0_NS + round(stamp / 1000) * 1000


@cache
def _base_drive() -> Drive:
    scenario = build_scenario("default", seed=0, duration_s=DURATION_S)
    source = ScenarioSource(scenario)
    kept = scenario.camera_stamps_ns[::FRAME_STEP]
    images = {f.stamp_ns: f.image for f in render_frames(scenario.drive, stamps_ns=kept)}
    records: list[Message] = []
    truth: dict[int, SE3] = {}
    for _topic, msg in source:
        if isinstance(msg, TagDetectionsMsg):
            if msg.stamp_ns in images:
                image = np.array(images[msg.stamp_ns])
                records.append(ImageMsg(_stamp(msg.stamp_ns), msg.frame_id, image, "mono8"))
        elif isinstance(msg, OdometryMsg):
            records.append(TransformMsg(_stamp(msg.stamp_ns), "odom", msg.child_frame_id,
                                        msg.T_parent_child))  # fmt: skip
        elif isinstance(msg, GroundTruthMsg):
            truth[_stamp(msg.stamp_ns)] = msg.T_frame_child
        elif isinstance(msg, (CameraInfoMsg, TransformMsg, PointCloudMsg)):
            records.append(dataclasses.replace(msg, stamp_ns=_stamp(msg.stamp_ns)))
    config = calibrated_config(scenario, scenario_config())
    premap = scenario_premap(scenario)
    return Drive(tuple(records), truth, scenario.tag_map, premap, config.to_yaml_text())


@cache
def drive(odom_frame: str = "odom") -> Drive:
    """The drive with ``odom_frame`` as the odometry origin (``odom`` or ``world``)."""
    base = _base_drive()
    records = tuple(
        dataclasses.replace(r, parent=odom_frame)
        if isinstance(r, TransformMsg) and r.parent == "odom" else r
        for r in base.records
    )  # fmt: skip
    return dataclasses.replace(base, records=records)
