"""A scenario as the simulator's message stream (:class:`ScenarioSource`): camera info and static
transforms, odometry and truth, tag detections and lidar sweeps in arrival order, the building's
elevator state, then the scenario's stream faults."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import numpy.typing as npt

from tagloc.messages import (
    CameraInfoMsg,
    ElevatorStateMsg,
    GroundTruthMsg,
    Message,
    NodeTopics,
    OdometryMsg,
    PointCloudMsg,
    TagDetectionsMsg,
    TransformMsg,
)
from tagloc.sim.elevator_stream import elevator_messages
from tagloc.sim.faults import apply_faults
from tagloc.sim.frame_truth import FrameTruthMap
from tagloc.sim.lidar import LIDAR_FRAME, LidarSimulator, Sweep
from tagloc.sim.lidar_floors import lidar_for_drive
from tagloc.sim.observations import ObservedFrame, simulate_observations
from tagloc.sim.scenario import Scenario

__all__ = ["BASE_FRAME", "CAMERA_FRAME", "MAP_FRAME", "ODOM_FRAME", "TF_STATIC", "ScenarioSource"]

MAP_FRAME, ODOM_FRAME, BASE_FRAME, CAMERA_FRAME = "map", "odom", "base_link", "camera_optical"
TF_STATIC = "/tf_static"
#: Odometry covariance written with the simulated odometry (informational; the filter's process
#: noise is configured in ``localizer.yaml``).
_ODOM_COV = np.diag(np.square([0.02, 0.02, 0.01, 0.005, 0.005, 0.02]))


class ScenarioSource:
    """A scenario as a :class:`~tagloc.messages.MessageSource` (the simulator's stream).

    Yields, in arrival order: the camera's ``CameraInfoMsg`` and the static ``base -> camera``
    transform at the start (and ``base -> lidar`` when the robot has a lidar), then per odometry
    stamp an ``OdometryMsg`` and a ``GroundTruthMsg``, per camera frame a ``TagDetectionsMsg``
    (before the odometry of the same stamp, as a bag's log-time order has it) and per lidar
    sweep a ``PointCloudMsg`` on ``topics.lidar`` (stamped at the sweep's start, delivered at its
    end: the time of its last point, ``last_point_ns()``, also the log time
    :class:`~tagloc.io.BagSink` gives it; simulated lazily as the stream is read:
    :mod:`tagloc.sim.lidar`); then the scenario's ``faults`` rewrite that stream.
    :attr:`frame_truth` holds what only the simulator knows (glints, tags truly in view).
    Camera frames are simulated as the stream is read, and only the recent frames' truth is
    kept (:class:`~tagloc.sim.frame_truth.FrameTruthMap`): memory does not grow with the drive.
    """

    def __init__(
        self, scenario: Scenario, topics: NodeTopics | None = None, lidar: bool = True
    ) -> None:
        """``lidar``: False leaves the sweeps out even when the robot has a lidar (a run that
        ignores them need not simulate them: 4 ms of CPU per sweep)."""
        self.scenario, self.t = scenario, topics or NodeTopics()
        drive = scenario.drive
        tag_frames = {t.id: t.frame for t, _ in scenario.world.all_tags()}
        self.frame_truth = FrameTruthMap(
            scenario.camera_stamps_ns, self._observe, tag_frames=tag_frames
        )
        self.glints_injected = 0  # false detections streamed so far
        robot = scenario.world.robot
        self.camera = robot.camera.camera_model()
        self.T_base_cam = robot.camera.T_base_cam.T_base_cam()
        self.lidar: LidarSimulator | None = None
        if robot.lidar is not None and lidar:
            self.lidar = lidar_for_drive(robot.lidar, scenario.world, scenario.people, drive)

    def _observe(self, stamps_ns: npt.NDArray[np.int64]) -> Iterator[ObservedFrame]:
        scenario = self.scenario
        return simulate_observations(
            scenario.drive, scenario.observation, stamps_ns=stamps_ns, world=scenario.world
        )

    @property
    def n_frames(self) -> int:
        """Camera frames the stream holds."""
        return len(self.scenario.camera_stamps_ns)

    @property
    def frames(self) -> list[ObservedFrame]:
        """Every camera frame of the drive, simulated again (the whole drive in memory)."""
        return list(self._observe(self.scenario.camera_stamps_ns))

    @property
    def topics(self) -> dict[str, type[Message]]:
        """Stream topic -> record type."""
        t = self.t
        topics: dict[str, type[Message]] = {
            t.odom: OdometryMsg, t.truth: GroundTruthMsg, t.detections: TagDetectionsMsg,
            t.camera_info: CameraInfoMsg, TF_STATIC: TransformMsg,
        }  # fmt: skip
        if self.lidar is not None:
            topics[t.lidar] = PointCloudMsg
        if self.scenario.elevator_topic:
            topics[t.elevator] = ElevatorStateMsg
        return topics

    def __iter__(self) -> Iterator[tuple[str, Message]]:
        t0 = int(self.scenario.drive.stamps_ns[0])
        return apply_faults(self._clean(), self.scenario.faults, t0)

    def _clean(self) -> Iterator[tuple[str, Message]]:
        drive, t = self.scenario.drive, self.t
        t0 = int(drive.stamps_ns[0])
        yield t.camera_info, CameraInfoMsg(t0, CAMERA_FRAME, self.camera.to_camera_info())
        yield TF_STATIC, TransformMsg(t0, BASE_FRAME, CAMERA_FRAME, self.T_base_cam, static=True)
        self.glints_injected = 0
        sweeps: Iterator[Sweep] = iter(())
        if self.lidar is not None:
            T_base_lidar = self.lidar.T_base_lidar
            yield TF_STATIC, TransformMsg(t0, BASE_FRAME, LIDAR_FRAME, T_base_lidar, static=True)
            starts = self.lidar.sweep_starts_ns(t0, int(drive.stamps_ns[-1]))
            sweeps = self.lidar.sweeps(lambda st: drive.ground_truth_at(st).xy_yaw_map_base, starts)
        sweep = next(sweeps, None)
        frames = self._observe(self.scenario.camera_stamps_ns)
        frame = next(frames, None)
        building = iter(elevator_messages(drive) if self.scenario.elevator_topic else ())
        state = next(building, None)
        for i, stamp in enumerate(drive.stamps_ns.tolist()):
            while state is not None and state.stamp_ns <= stamp:  # the building's elevators
                yield t.elevator, state
                state = next(building, None)
            # frames arrive at their stamp, sweeps when complete, before the odometry of a stamp
            while True:
                t_frame = frame.stamp_ns if frame is not None else stamp + 1
                t_sweep = sweep.msg.last_point_ns() if sweep is not None else stamp + 1
                if min(t_frame, t_sweep) > stamp:
                    break
                if t_frame <= t_sweep:
                    assert frame is not None
                    self.frame_truth.record(frame)
                    self.glints_injected += sum(frame.false_detection)
                    yield (
                        t.detections,
                        TagDetectionsMsg(frame.stamp_ns, CAMERA_FRAME, frame.detections),
                    )
                    frame = next(frames, None)
                else:
                    assert sweep is not None
                    yield t.lidar, sweep.msg
                    sweep = next(sweeps, None)
            T = drive.T_odom_base[i]
            yield t.odom, OdometryMsg(stamp, ODOM_FRAME, BASE_FRAME, T, _ODOM_COV)
            yield t.truth, GroundTruthMsg(stamp, MAP_FRAME, drive.T_map_base[i])
