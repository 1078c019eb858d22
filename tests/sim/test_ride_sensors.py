"""The sensors in a building, against ground truth: the camera in the moving cab sees the cab tag
where the true poses put it (oracle: OpenCV's projectPoints), passengers hide it part of the
time, the lidar in the cab sees the cab's walls, the building's elevator state on the stream, a
kidnap onto another floor."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tagloc.messages import ElevatorStateMsg
from tagloc.sim import load_builtin_world, simulate_drive, simulate_observations
from tagloc.sim.drive import Drive
from tagloc.sim.lidar_floors import FloorLidarSimulator
from tagloc.sim.ride import RidePlan
from tagloc.sim.scenarios import ScenarioSource, build_scenario
from tagloc.tags.detection import tag_object_points

CAB_TAG = 100


@pytest.fixture(scope="module")
def drive() -> Drive:
    return simulate_drive(load_builtin_world("tower"), seed=1)


def _trip_stamps(drive: Drive, ride: int = 0, every_s: float = 0.2) -> np.ndarray:
    assert isinstance(drive.plan, RidePlan)
    r = drive.plan.rides[ride]
    t = np.arange(r.depart_s + 0.1, r.arrive_s - 0.1, every_s)
    return drive.t0_ns + np.round(t * 1e9).astype(np.int64)


def test_the_camera_in_the_moving_cab_sees_the_cab_tag_where_the_true_poses_put_it(
    drive: Drive,
) -> None:
    world = drive.world
    stamps = _trip_stamps(drive)
    frames = list(simulate_observations(drive, stamps_ns=stamps))
    camera = world.robot.camera.camera_model()
    T_base_cam = world.robot.camera.T_base_cam.T_base_cam()
    T_cab_tag = world.find_tag(CAB_TAG).T_frame_tag()
    heights = []
    for frame in frames:
        (sighting,) = frame.truth  # the door is closed: the cab's tag alone is in view
        assert sighting.tag_id == CAB_TAG and sighting.detected
        T_map_cab = drive.T_map_cab(frame.stamp_ns)
        truth = drive.ground_truth_at(np.array([frame.stamp_ns]))
        T_cam_tag = (truth.T_map_base[0] @ T_base_cam).inverse() @ T_map_cab @ T_cab_tag
        expected, _ = cv2.projectPoints(
            tag_object_points(sighting.size), T_cam_tag.rotation.as_rotvec(),
            np.asarray(T_cam_tag.translation), camera.K, None,
        )  # fmt: skip
        np.testing.assert_allclose(sighting.corners_px, expected.reshape(4, 2), atol=1e-6)
        heights.append(T_map_cab.translation[2])
    assert heights[-1] - heights[0] > 3.0  # the cab really moved
    # the robot stands in the cab: the tag stays put in the image while the cab moves
    first = frames[0].truth[0].corners_px
    for frame in frames[1:]:
        np.testing.assert_allclose(frame.truth[0].corners_px, first, atol=1e-9)


def test_passengers_hide_the_cab_tag_part_of_the_time() -> None:
    scenario = build_scenario("elevator", seed=0, duration_s=130.0)
    drive = scenario.drive
    assert isinstance(drive.plan, RidePlan) and len(scenario.world.people) == 2
    inside = [r for r in drive.plan.rides if r.arrive_s < 125.0]
    assert inside
    stamps = np.concatenate([_trip_stamps(drive, k, 0.1) for k in range(len(inside))])
    frames = list(
        simulate_observations(drive, scenario.observation, stamps_ns=stamps, world=scenario.world)
    )
    seen = np.array([any(s.tag_id == CAB_TAG for s in f.truth) for f in frames])
    assert 0.1 < seen.mean() < 0.9, seen.mean()


def test_the_lidar_in_the_cab_sees_the_cab_walls(drive: Drive) -> None:
    world = drive.world
    shaft = world.elevators[0].model_copy(update={"wall_material": "wall"})
    world = world.model_copy(update={"elevators": (shaft,)})
    drive = simulate_drive(world, seed=1)
    lidar = world.robot.lidar
    assert lidar is not None
    sim = FloorLidarSimulator(lidar, world, drive)
    start = int(_trip_stamps(drive)[10])
    sweep = next(sim.sweeps(lambda st: drive.ground_truth_at(st).xy_yaw_map_base, [start]))
    msg = sweep.msg
    assert len(msg.points) > 1000
    # each point into the floor-local frame of its column (the cab floor at z = 0), then the cab's
    column = sweep.beam_index // len(lidar.elevations_rad())  # beams column by column
    R, t = sweep.R_map_lidar[column], sweep.t_map_lidar[column]
    local = np.einsum("nij,nj->ni", R, msg.points.astype(np.float64)) + t
    p = shaft.pose_in_map
    xy = local[:, :2] - [p.x, p.y]
    hx, hy = shaft.footprint[0] / 2, shaft.footprint[1] / 2
    slack = 4 * lidar.range_sigma_m + 1e-6
    assert (np.abs(xy[:, 0]) <= hx + slack).all() and (np.abs(xy[:, 1]) <= hy + slack).all()
    assert (local[:, 2] >= -slack).all() and (local[:, 2] <= shaft.height + slack).all()
    on_walls = (np.abs(np.abs(xy[:, 0]) - hx) < slack) | (np.abs(np.abs(xy[:, 1]) - hy) < slack)
    assert on_walls.mean() > 0.3  # the walls (door included), the rest the cab floor


def test_the_stream_carries_the_buildings_elevator_state_when_it_provides_one() -> None:
    scenario = build_scenario("elevator", seed=0, duration_s=120.0)
    source = ScenarioSource(scenario, lidar=False)
    assert source.topics[source.t.elevator] is ElevatorStateMsg
    states = [m for topic, m in source if topic == source.t.elevator]
    assert isinstance(states[0], ElevatorStateMsg)
    drive = scenario.drive
    assert {m.door_open for m in states} == {True, False}
    assert None in {m.floor for m in states if isinstance(m, ElevatorStateMsg)}
    for m in states:
        assert isinstance(m, ElevatorStateMsg) and m.cab_frame == "elevator_cab"
        assert m.door_open == drive.door_open(m.stamp_ns)
        assert isinstance(drive.plan, RidePlan)
        assert m.floor == drive.plan.cab_floor_at(drive.route_s(m.stamp_ns))[0]
    gaps = np.diff([m.stamp_ns for m in states])
    assert gaps.max() <= 0.5e9 and (gaps >= 0).all()
    other = ScenarioSource(build_scenario("kidnap_floor", duration_s=5.0), lidar=False)
    assert other.t.elevator not in other.topics
    assert not any(isinstance(m, ElevatorStateMsg) for _, m in other)


def test_kidnap_floor_carries_the_robot_to_the_same_spot_of_another_floor() -> None:
    scenario = build_scenario("kidnap_floor", seed=0, duration_s=100.0)
    drive = scenario.drive
    (kidnap,) = scenario.kidnaps_ns
    before, after = kidnap - 10_000_000, kidnap
    assert (drive.floor_at(before), drive.floor_at(after)) == ("2", "0")
    truth = drive.ground_truth_at(np.array([before, after]))
    xy = truth.xy_yaw_map_base[:, :2]
    assert np.linalg.norm(xy[1] - xy[0]) < 0.1  # within a stride: the same spot, heading
    assert truth.T_map_base.translation[0][2] - truth.T_map_base.translation[1][2] == 7.0
    k = int(np.searchsorted(drive.stamps_ns, kidnap))
    odo = np.asarray(drive.T_odom_base.translation)
    assert np.linalg.norm(odo[k] - odo[k - 1]) < 0.01  # the odometry did not notice
