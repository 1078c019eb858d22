"""simulate_drive: shapes, stamps, start alignment, purity and seeding."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tagloc.sim import Drive, World, load_default_world, simulate_drive


@pytest.fixture(scope="module")
def world() -> World:
    return load_default_world()


@pytest.fixture(scope="module")
def drive(world: World) -> Drive:
    return simulate_drive(world)


def test_drive_shapes_and_stamps(drive: Drive, world: World) -> None:
    n = len(drive.stamps_ns)
    assert drive.stamps_ns.dtype == np.int64 and drive.camera_stamps_ns.dtype == np.int64
    assert len(drive.T_map_base) == len(drive.T_odom_base) == len(drive.distance_m) == n
    assert np.all(np.diff(drive.stamps_ns) == round(1e9 / world.robot.odom_rate_hz))
    assert np.all(np.diff(drive.camera_stamps_ns) == round(1e9 / world.robot.camera.rate_hz))
    assert drive.camera_stamps_ns[0] == drive.stamps_ns[0] == drive.t0_ns == 0
    assert drive.camera_stamps_ns[-1] <= drive.stamps_ns[-1]
    assert np.all(np.diff(drive.distance_m) >= 0) and drive.distance_m[-1] >= 300.0
    assert drive.seed == world.robot.odometry.seed
    with pytest.raises(dataclasses.FrozenInstanceError):
        drive.seed = 3  # type: ignore[misc]
    assert not drive.stamps_ns.flags.writeable


def test_odometry_starts_at_ground_truth_and_drifts(drive: Drive) -> None:
    assert drive.T_odom_base[0].allclose(drive.T_map_base[0])
    drift = np.linalg.norm(drive.T_odom_base.translation - drive.T_map_base.translation, axis=1)
    assert drift[1:100].max() < 0.05 < 1.0 < drift[-1]


def test_seed_changes_odometry_only(world: World, drive: Drive) -> None:
    again = simulate_drive(world)
    other = simulate_drive(world, seed=11, t0_ns=5_000_000_000)
    np.testing.assert_array_equal(again.T_odom_base.translation, drive.T_odom_base.translation)
    np.testing.assert_array_equal(other.T_map_base.translation, drive.T_map_base.translation)
    np.testing.assert_array_equal(other.stamps_ns, drive.stamps_ns + 5_000_000_000)
    assert other.seed == 11
    assert np.abs(other.T_odom_base.translation - drive.T_odom_base.translation).max() > 0.1


def test_ground_truth_at_camera_stamps_is_exact(drive: Drive) -> None:
    on_grid = drive.ground_truth_at(drive.stamps_ns[::7])
    np.testing.assert_allclose(on_grid.xy_yaw_map_base, drive.trajectory.xy_yaw_map_base[::7])
    at_camera = drive.ground_truth_at(drive.camera_stamps_ns)
    assert len(at_camera.T_map_base) == len(drive.camera_stamps_ns)
    assert np.abs(at_camera.linear_velocity_base[:, 0]).max() <= drive.world.route.speed + 1e-9


def test_world_camera_becomes_a_camera_model_that_projects_like_opencv() -> None:
    import cv2

    from tagloc.sim.robot import Camera

    rng = np.random.default_rng(3)
    points_cam = np.column_stack([rng.uniform(-1, 1, (50, 2)), rng.uniform(1, 5, 50)])
    for distortion, project in [
        ({"model": "radtan", "coefficients": [-0.2, 0.05, 1e-3, -2e-3, 0.01]}, cv2.projectPoints),
        (
            {"model": "equidistant", "coefficients": [-0.01, 0.02, -0.003, 0.001]},
            cv2.fisheye.projectPoints,
        ),
    ]:
        camera = Camera.model_validate(
            {
                "intrinsics": {
                    "fx": 600,
                    "fy": 610,
                    "cx": 640,
                    "cy": 360,
                    "width": 1280,
                    "height": 720,
                },
                "distortion": distortion,
                "rate_hz": 30,
                "T_base_cam": {"position": [0, 0, 0.5], "rpy_deg": [0, 0, 0]},
            }
        )
        model = camera.camera_model()
        expected, _ = project(
            points_cam.reshape(-1, 1, 3),
            np.zeros(3),
            np.zeros(3),
            np.array([[600.0, 0, 640], [0, 610, 360], [0, 0, 1]]),
            np.array(distortion["coefficients"]),
        )
        np.testing.assert_allclose(model.project(points_cam), expected.reshape(-1, 2), atol=1e-8)
        assert model.image_size == (1280, 720)
