"""Planned trajectories are smooth, bounded, deterministic, and pass through their waypoints."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tagloc.sim import load_default_world
from tagloc.sim.trajectory import (
    MAX_ROUNDED_TURN_RAD,
    RoutePlan,
    Trajectory,
    generate_trajectory,
    plan_from_config,
    plan_route,
)

LIMITS = {"speed": 1.0, "accel_max": 0.5, "yaw_rate_max": 0.8, "yaw_accel_max": 1.2}
SQUARE = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0], [0.0, 4.0], [0.0, 0.0]])
RATE_HZ = 200.0


def _check_smooth(plan: RoutePlan, traj: Trajectory, corner_radius: float = 0.0) -> None:
    """Bounds and consistency of velocities/accelerations with finite differences."""
    dt = 1.0 / RATE_HZ
    v = traj.linear_velocity_base[:, 0]
    omega = traj.angular_velocity_base[:, 2]
    a = traj.linear_acceleration_base
    tol = 1e-9
    assert np.all(v >= -tol) and v.max() <= LIMITS["speed"] + tol
    assert np.abs(a[:, 0]).max() <= LIMITS["accel_max"] + tol
    assert np.abs(omega).max() <= LIMITS["yaw_rate_max"] + tol
    if corner_radius > 0:  # centripetal acceleration on fillets: v^2 / r with v <= w_max r
        assert np.abs(a[:, 1]).max() <= LIMITS["yaw_rate_max"] ** 2 * corner_radius + tol
    # positions and yaw change no faster than the limits allow (no jumps between pieces)
    xy, yaw = traj.xy_yaw_map_base[:, :2], traj.xy_yaw_map_base[:, 2]
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    assert step.max() <= LIMITS["speed"] * dt + 1e-9
    assert np.abs(np.diff(yaw)).max() <= LIMITS["yaw_rate_max"] * dt + 1e-9
    # velocity in base agrees with the central difference of the map positions
    heading = np.column_stack([np.cos(yaw), np.sin(yaw)])
    vel_map = (xy[2:] - xy[:-2]) / (2 * dt)
    np.testing.assert_allclose(vel_map, v[1:-1, None] * heading[1:-1], atol=2e-3)
    # ... and the yaw rate with that of yaw, except where a fillet starts or ends (yaw-rate step)
    steady = np.abs(omega[2:] - omega[:-2]) <= 2 * dt * LIMITS["yaw_accel_max"] + 1e-9
    assert corner_radius > 0 or steady.all()
    np.testing.assert_allclose(
        ((yaw[2:] - yaw[:-2]) / (2 * dt))[steady], omega[1:-1][steady], atol=2e-3
    )
    # tangential acceleration agrees with dv/dt, and acceleration stays continuous
    np.testing.assert_allclose((v[2:] - v[:-2]) / (2 * dt), a[1:-1, 0], atol=5e-3)
    jerk = np.abs(np.diff(a[:, 0])) / dt
    assert jerk.max() <= LIMITS["accel_max"] * math.pi / 2 * 10  # finite: no accel steps
    # yaw acceleration is bounded while turning in place (fillets step the yaw rate)
    if corner_radius == 0:
        assert np.abs(np.diff(omega)).max() / dt <= LIMITS["yaw_accel_max"] + 1e-6
    # SE3 view agrees with the planar one; base on the floor
    np.testing.assert_allclose(traj.T_map_base.translation[:, :2], xy)
    assert np.all(traj.T_map_base.translation[:, 2] == 0.0)


def test_stop_and_turn_square_passes_through_waypoints() -> None:
    plan = plan_route(SQUARE, [1.0, 0, 0, 0, 1.0], **LIMITS)
    traj = generate_trajectory(plan, RATE_HZ)
    _check_smooth(plan, traj)
    at = plan.sample(np.round(plan.waypoint_times_s * 1e9).astype(np.int64))
    np.testing.assert_allclose(at.xy_yaw_map_base[:, :2], SQUARE, atol=1e-9)
    np.testing.assert_allclose(at.linear_velocity_base, 0.0, atol=1e-9)  # stops at corners
    assert plan.length_m == pytest.approx(20.0)
    assert traj.distance_m[-1] == pytest.approx(20.0)
    np.testing.assert_allclose(
        traj.distance_m[1:] - traj.distance_m[:-1],
        np.linalg.norm(np.diff(traj.xy_yaw_map_base[:, :2], axis=0), axis=1),
        atol=1e-9,
    )
    # three left turns of 90 degrees, unwrapped heading
    assert traj.xy_yaw_map_base[-1, 2] == pytest.approx(1.5 * math.pi)
    # dwell at start and end: the first and last second stand still
    assert traj.linear_velocity_base[: int(RATE_HZ) - 1].max() == 0.0


def test_rounded_corners_keep_moving_and_stay_near_waypoints() -> None:
    radius = 0.5
    plan = plan_route(SQUARE, [0.0] * 5, corner_radius=radius, **LIMITS)
    traj = generate_trajectory(plan, RATE_HZ)
    _check_smooth(plan, traj, corner_radius=radius)
    at = plan.sample(np.round(plan.waypoint_times_s * 1e9).astype(np.int64))
    miss = np.linalg.norm(at.xy_yaw_map_base[:, :2] - SQUARE, axis=1)
    np.testing.assert_allclose(miss[[0, -1]], 0.0, atol=1e-9)
    # the fillet misses a 90-degree corner by r (sqrt(2) - 1)
    np.testing.assert_allclose(miss[1:-1], radius * (math.sqrt(2) - 1), atol=1e-6)
    corner_speed = at.linear_velocity_base[1:-1, 0]
    np.testing.assert_allclose(corner_speed, LIMITS["yaw_rate_max"] * radius)
    assert plan.length_m == pytest.approx(20.0 - 3 * radius * (2 - math.pi / 2))


def test_sharp_turns_and_dwells_stop_even_with_rounding() -> None:
    points = np.array([[0.0, 0.0], [5.0, 0.0], [5.0, 5.0], [0.0, 0.0], [4.0, 1.0]])
    plan = plan_route(points, [0, 0, 2.0, 0, 0], corner_radius=0.5, **LIMITS)
    traj = plan.sample(np.round(plan.waypoint_times_s * 1e9).astype(np.int64))
    turn_at_3 = math.pi - math.atan2(1, 4) - math.pi / 4  # > MAX_ROUNDED_TURN_RAD
    assert turn_at_3 > MAX_ROUNDED_TURN_RAD
    speeds = traj.linear_velocity_base[:, 0]
    assert speeds[1] > 0 and speeds[2] == 0.0 and speeds[3] == 0.0
    np.testing.assert_allclose(traj.xy_yaw_map_base[[2, 3], :2], points[[2, 3]], atol=1e-9)
    _check_smooth(plan, generate_trajectory(plan, RATE_HZ), corner_radius=0.5)


def test_short_segments_lower_the_peak_speed() -> None:
    points = np.array([[0.0, 0.0], [0.3, 0.0], [0.3, 0.2]])
    plan = plan_route(points, [0.0, 0.0, 0.0], **LIMITS)
    traj = generate_trajectory(plan, RATE_HZ)
    _check_smooth(plan, traj)
    assert traj.linear_velocity_base[:, 0].max() < 0.5 * LIMITS["speed"]
    np.testing.assert_allclose(traj.xy_yaw_map_base[-1, :2], points[-1], atol=1e-9)


def test_reversals_unwind_the_heading() -> None:
    """Out-and-back legs turn alternately, so the heading does not wind up."""
    points = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 0.0], [3.0, 0.0], [0.0, 0.0]])
    plan = plan_route(points, [0.0] * 5, **LIMITS)
    yaw = generate_trajectory(plan, RATE_HZ).xy_yaw_map_base[:, 2]
    assert yaw.max() == pytest.approx(math.pi) and yaw.min() == pytest.approx(0.0)
    assert yaw[-1] == pytest.approx(math.pi)


def test_deterministic_and_clamped() -> None:
    a = plan_route(SQUARE, [0.0] * 5, corner_radius=0.4, **LIMITS)
    b = plan_route(SQUARE, [0.0] * 5, corner_radius=0.4, **LIMITS)
    ta, tb = generate_trajectory(a, 50.0, t0_ns=123), generate_trajectory(b, 50.0, t0_ns=123)
    np.testing.assert_array_equal(ta.xy_yaw_map_base, tb.xy_yaw_map_base)
    assert ta.stamps_ns.dtype == np.int64 and ta.stamps_ns[0] == 123
    assert np.all(np.diff(ta.stamps_ns) == 20_000_000)
    outside = a.sample(np.array([-(10**9), 10**12], dtype=np.int64))
    np.testing.assert_allclose(outside.xy_yaw_map_base[:, :2], SQUARE[[0, -1]], atol=1e-9)
    with pytest.raises(ValueError, match="two distinct waypoints"):
        plan_route(np.zeros((3, 2)), [0.0] * 3, **LIMITS)


def test_default_route_is_smooth() -> None:
    world = load_default_world()
    plan = plan_from_config(world.route, world.checkpoints_xy())
    traj = generate_trajectory(plan, RATE_HZ)
    route = world.route
    assert (route.speed, route.yaw_rate_max) == (0.8, 0.8)
    v, omega = traj.linear_velocity_base[:, 0], traj.angular_velocity_base[:, 2]
    assert v.max() == pytest.approx(route.speed) and np.abs(omega).max() <= route.yaw_rate_max
    assert np.abs(traj.linear_acceleration_base[:, 0]).max() <= route.accel_max + 1e-9
    step = np.linalg.norm(np.diff(traj.xy_yaw_map_base[:, :2], axis=0), axis=1)
    assert step.max() <= route.speed / RATE_HZ + 1e-9
    assert traj.distance_m[-1] == pytest.approx(plan.length_m) and plan.length_m >= 300
