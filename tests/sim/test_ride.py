"""Rides against the simulator's ground truth: the cab's z profile within its speed and
acceleration, doors closed while it moves and open when the robot passes, the robot's floor and
height along a ride, odometry through a ride."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tagloc.sim import load_builtin_world, simulate_drive
from tagloc.sim.drive import Drive
from tagloc.sim.odometry_ride import ImuFusionConfig
from tagloc.sim.ride import RidePlan, landing_and_centre

DT_S = 1e-3


@pytest.fixture(scope="module")
def drive() -> Drive:
    return simulate_drive(load_builtin_world("tower"), seed=3)


def _plan(drive: Drive) -> RidePlan:
    assert isinstance(drive.plan, RidePlan)
    return drive.plan


def _stamps(t0_s: float, t1_s: float, drive: Drive) -> np.ndarray:
    t = np.arange(t0_s, t1_s, DT_S)
    return drive.t0_ns + np.round(t * 1e9).astype(np.int64)


def test_the_cab_moves_within_its_speed_and_acceleration(drive: Drive) -> None:
    plan = _plan(drive)
    shaft = drive.world.elevators[0]
    cab = plan.cab("lift")
    heights = drive.world.floor_heights()
    assert len(plan.rides) == 6
    for ride in plan.rides:
        t = np.arange(ride.depart_s - 1.0, ride.arrive_s + 1.0, DT_S)
        z = cab.z.z(t)
        # oracle: finite differences of the position alone
        v = np.diff(z) / DT_S
        a = np.diff(v) / DT_S
        assert np.abs(v).max() <= shaft.speed_mps + 1e-9
        assert np.abs(a).max() <= shaft.accel_mps2 * (1 + 1e-6)
        assert z[0] == heights[ride.from_floor] and z[-1] == heights[ride.to_floor]
        # the trip's duration is that of a rest-to-rest trapezoid (triangle when short)
        d = abs(heights[ride.to_floor] - heights[ride.from_floor])
        v_max, a_max = shaft.speed_mps, shaft.accel_mps2
        expected = v_max / a_max + d / v_max if d >= v_max**2 / a_max else 2 * math.sqrt(d / a_max)
        assert ride.arrive_s - ride.depart_s == pytest.approx(expected, rel=1e-12)
        assert np.abs(v).max() == pytest.approx(min(v_max, math.sqrt(d * a_max)), rel=1e-3)


def test_the_door_is_closed_while_the_cab_moves_and_open_when_the_robot_passes(
    drive: Drive,
) -> None:
    plan = _plan(drive)
    cab = plan.cab()
    t = np.arange(0.0, plan.total_duration_s, 0.01)
    moving = cab.z.moving(t)
    assert moving.any() and (cab.doors.fraction(t)[moving] == 0.0).all()
    # the robot crosses the door line only through an open door
    shaft = drive.world.elevators[0]
    landing, centre = landing_and_centre(shaft)
    stamps = drive.t0_ns + np.round(t * 1e9).astype(np.int64)
    xy = drive.ground_truth_at(stamps).xy_yaw_map_base[:, :2]
    door_x = centre[0] - shaft.footprint[0] / 2  # the door faces -x in map (yaw 180)
    crossing = np.flatnonzero(np.diff(np.sign(xy[:, 0] - door_x)) != 0)
    assert len(crossing) == 2 * len(plan.rides)
    assert cab.doors.is_open(t[crossing]).all()
    assert (cab.doors.fraction(t[crossing]) == 1.0).all()
    # the door counts as open from half-way
    opening = plan.rides[0].call_s
    assert not cab.doors.is_open(opening + 0.49 * shaft.door_open_s)[0]
    assert cab.doors.is_open(opening + 0.51 * shaft.door_open_s)[0]
    assert landing[0] < door_x < centre[0]


def test_the_floor_and_height_are_right_along_every_ride(drive: Drive) -> None:
    plan = _plan(drive)
    heights = drive.world.floor_heights()
    for ride in plan.rides:
        before, during, after = (
            ride.call_s - 1.0, 0.5 * (ride.depart_s + ride.arrive_s), ride.exit_s + 1.0
        )  # fmt: skip
        stamps = drive.t0_ns + np.round(np.array([before, during, after]) * 1e9).astype(np.int64)
        truth = drive.ground_truth_at(stamps)
        z = truth.T_map_base.translation[:, 2]
        assert [drive.floor_at(int(s)) for s in stamps] == [ride.from_floor, None, ride.to_floor]
        assert z[0] == heights[ride.from_floor] and z[2] == heights[ride.to_floor]
        assert [drive.cab_of(int(s)) for s in stamps] == [None, "lift", None]
        # in the cab the robot's z is the cab's
        trip = _stamps(ride.depart_s, ride.arrive_s, drive)[::50]
        truth = drive.ground_truth_at(trip)
        cab_z = [drive.T_map_cab(int(s)).translation[2] for s in trip]
        np.testing.assert_allclose(truth.T_map_base.translation[:, 2], cab_z, atol=1e-12)
        assert not any(drive.door_open(int(s)) for s in trip)
        # its vertical velocity and acceleration are the cab's derivatives
        vz = truth.linear_velocity_base[:, 2]
        z_fine = plan.cab().z.z(np.r_[(trip - drive.t0_ns) * 1e-9] + np.array([[-1e-4], [1e-4]]))
        np.testing.assert_allclose(vz, (z_fine[1] - z_fine[0]) / 2e-4, atol=1e-4)  # at kinks: a h


def test_legged_odometry_sees_no_motion_in_a_ride_and_keeps_its_z(drive: Drive) -> None:
    plan = _plan(drive)
    for ride in plan.rides:
        k0, k1 = np.searchsorted(
            drive.stamps_ns, _stamps(ride.depart_s, ride.arrive_s, drive)[[0, -1]]
        )
        still = drive.T_odom_base[int(k0) : int(k1) + 1]
        first = still[0].as_matrix()
        assert all(np.array_equal(T.as_matrix(), first) for T in still)
    assert (np.asarray(drive.T_odom_base.translation)[:, 2] == 0.0).all()


def _imu_drive(bias_sigma: float) -> Drive:
    world = load_builtin_world("tower")
    imu = ImuFusionConfig(accel_bias_sigma_mps2=bias_sigma)
    odometry = world.robot.odometry.model_copy(update={"imu": imu})
    world = world.model_copy(
        update={"robot": world.robot.model_copy(update={"odometry": odometry})}
    )
    return simulate_drive(world, seed=3)


@pytest.mark.parametrize("bias_sigma", [0.0, 0.05])
def test_imu_odometry_drifts_in_z_as_documented(bias_sigma: float) -> None:
    drive = _imu_drive(bias_sigma)
    plan = _plan(drive)
    imu = drive.world.robot.odometry.imu
    assert imu is not None
    tau = imu.velocity_time_constant_s
    bias = float(np.random.default_rng([drive.seed, 1]).normal(0.0, bias_sigma))
    z_odom = np.asarray(drive.T_odom_base.translation)[:, 2]
    t = (drive.stamps_ns - drive.t0_ns) * 1e-9
    shaft = drive.world.elevators[0]
    drift = 0.0
    for ride in plan.rides:
        trip = ride.arrive_s - ride.depart_s
        window = (t >= ride.depart_s - 0.5) & (t <= ride.arrive_s + 10 * tau)
        before = z_odom[np.searchsorted(t, ride.depart_s) - 1]
        # the transient: at most tau times the cab's peak speed, plus what the bias gives
        excursion = np.abs(z_odom[window] - before).max()
        assert excursion <= tau * shaft.speed_mps + abs(bias) * tau * trip + 1e-9
        assert excursion > 0.05 * tau * shaft.speed_mps  # the ride does show
        # settled: exactly b T tau
        settled = z_odom[np.searchsorted(t, ride.arrive_s + 10 * tau)]
        assert settled - before == pytest.approx(bias * trip * tau, abs=1e-3)
        drift += bias * trip * tau
    assert z_odom[-1] == pytest.approx(drift, abs=1e-3)


def test_imu_odometry_tilts_while_the_cab_accelerates() -> None:
    drive = _imu_drive(0.0)
    plan = _plan(drive)
    imu = drive.world.robot.odometry.imu
    assert imu is not None
    R = drive.T_odom_base.rotation.as_matrix()
    tilt = np.degrees(np.arccos(np.clip(R[:, 2, 2], -1.0, 1.0)))
    t = (drive.stamps_ns - drive.t0_ns) * 1e-9
    peak = imu.tilt_deg_per_mps2 * drive.world.elevators[0].accel_mps2
    for ride in plan.rides:
        window = (t >= ride.depart_s) & (t <= ride.arrive_s + 1.0)
        assert 0.5 * peak < tilt[window].max() <= peak + 1e-9
        later = np.searchsorted(t, ride.arrive_s + 10 * imu.tilt_time_constant_s)
        assert tilt[later] < 1e-3 * peak
    outside = t < plan.rides[0].depart_s
    assert tilt[outside].max() == 0.0
