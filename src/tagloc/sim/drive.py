"""A simulated drive: ground truth along the world's route and the robot's drifting odometry.

Pure: no file I/O, no global state; the same world and seed give the same drive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from tagloc._types import FloatArray
from tagloc.errors import SimulationError
from tagloc.geometry import SE3
from tagloc.sim.odometry import simulate_odometry
from tagloc.sim.odometry_ride import ride_odometry
from tagloc.sim.ride import RidePlan, cab_contains
from tagloc.sim.trajectory import RoutePlan, Trajectory, regular_stamps
from tagloc.sim.world import World


@dataclass(frozen=True, slots=True)
class Drive:
    """One drive of the world's route (N odometry samples, M camera frames).

    Attributes
    ----------
    world : World
        The world that was driven.
    stamps_ns : (N,) int64
        Odometry / ground-truth stamps, nanoseconds, at ``world.robot.odom_rate_hz`` from ``t0_ns``.
    T_map_base : SE3 batch of N
        Ground-truth pose of ``base`` in ``map``.
    T_odom_base : SE3 batch of N
        Drifting odometry; ``T_odom_base[0] == T_map_base[0]`` (``odom`` = ``map`` at the start).
    camera_stamps_ns : (M,) int64
        Camera frame stamps at ``world.robot.camera.rate_hz`` over the same span.
    distance_m : (N,) float
        True path length travelled up to each stamp, metres.
    trajectory : Trajectory
        The full ground truth at ``stamps_ns`` (adds body velocities and accelerations).
    plan : RoutePlan
        The planned route; ``plan.sample(stamps_ns, t0_ns)`` gives exact ground truth at any stamp
        (for example at ``camera_stamps_ns``, with velocities for motion blur).
    t0_ns : int
        Start of the route.
    seed : int
        The odometry seed used.
    """

    world: World
    stamps_ns: NDArray[np.int64]
    T_map_base: SE3
    T_odom_base: SE3
    camera_stamps_ns: NDArray[np.int64]
    distance_m: NDArray[np.float64]
    trajectory: Trajectory
    plan: RoutePlan
    t0_ns: int
    seed: int

    def ground_truth_at(self, stamps_ns: NDArray[np.int64]) -> Trajectory:
        """Exact ground truth at arbitrary stamps (clamped to the drive's span)."""
        return self.plan.sample(stamps_ns, self.t0_ns)

    def route_s(self, stamps_ns: npt.ArrayLike) -> FloatArray:
        """Where along the route (seconds after its start) the robot is at ``stamps_ns`` (a
        kidnap skips part of it); the building's state is read at these times too."""
        stamps = np.atleast_1d(np.asarray(stamps_ns, dtype=np.int64))
        return (stamps - np.int64(self.t0_ns)).astype(np.float64) * 1e-9

    # ----- floors and elevators (tagloc.sim.ride); a single-floor world is floor "0" -----
    def T_map_cab(self, stamp_ns: int, elevator: str | None = None) -> SE3:
        """Pose of the cab of ``elevator`` (default: the first) in ``map`` at ``stamp_ns``.

        Raises ``SimulationError`` for a world without elevators.
        """
        if isinstance(self.plan, RidePlan):
            return self.plan.cab(elevator).T_map_cab(float(self.route_s(stamp_ns)[0]))
        shafts = self.world.shafts()
        if not shafts:
            raise SimulationError(f"world {self.world.name!r} has no elevator")
        return shafts[0].T_map_cab()

    def door_open(self, stamp_ns: int, elevator: str | None = None) -> bool:
        """Whether the cab's door is open at ``stamp_ns`` (a cab that never moves: always)."""
        if isinstance(self.plan, RidePlan):
            return bool(self.plan.cab(elevator).doors.is_open(self.route_s(stamp_ns))[0])
        return True

    def floor_at(self, stamp_ns: int) -> str | None:
        """The robot's floor at ``stamp_ns``: a floor's name, None while its cab moves."""
        if isinstance(self.plan, RidePlan):
            return self.plan.floor_at(self.route_s(stamp_ns))[0]
        return self.world.all_floors()[0].name

    def cab_of(self, stamp_ns: int) -> str | None:
        """The elevator (shaft name) whose cab the robot is in at ``stamp_ns``, or None."""
        xy = self.ground_truth_at(np.array([stamp_ns], dtype=np.int64)).xy_yaw_map_base[:, :2]
        if isinstance(self.plan, RidePlan):
            return self.plan.cab_of(self.route_s(stamp_ns), xy)[0]
        for shaft in self.world.shafts():
            if cab_contains(shaft, xy):
                return shaft.name
        return None


def simulate_drive(world: World, seed: int | None = None, *, t0_ns: int = 0) -> Drive:
    """Drive the world's route once with its robot.

    Parameters
    ----------
    world : World
    seed : int, optional
        Odometry seed; defaults to ``world.robot.odometry.seed``.
    t0_ns : int
        Stamp of the route start, nanoseconds.

    Returns
    -------
    Drive
    """
    robot = world.robot
    seed = robot.odometry.seed if seed is None else seed
    # 1. plan the route (checkpoint names resolved) and sample ground truth at the odometry rate
    plan = world.plan_route()
    stamps_ns = regular_stamps(plan.total_duration_s, robot.odom_rate_hz, t0_ns)
    trajectory = plan.sample(stamps_ns, t0_ns)
    # 2. corrupt the relative motions and integrate them into odometry (a ride: see ride_odometry)
    T_odom_base = simulate_odometry(robot.odometry, trajectory.xy_yaw_map_base, seed)
    if isinstance(plan, RidePlan):
        t_s = (stamps_ns - np.int64(t0_ns)).astype(np.float64) * 1e-9
        mid = t_s + np.r_[np.diff(t_s), 0.0] / 2  # each interval's middle
        _, _, accel_z = plan.robot_z.evaluate(mid)
        # the odometry reads the base's height above the floor it started on, as a robot's
        # odometry that starts at zero does (a planar localizer takes its z for that)
        z0 = float(trajectory.T_map_base.translation[0][2])
        z0 -= max((h for h in world.floor_heights().values() if h <= z0 + 1e-6), default=0.0)
        T_odom_base = ride_odometry(
            robot.odometry.imu, T_odom_base, t_s, z0, accel_z, plan.robot_z.moving(mid), seed
        )
    # 3. camera frames over the same span
    camera_stamps_ns = regular_stamps(plan.total_duration_s, robot.camera.rate_hz, t0_ns)
    camera_stamps_ns = camera_stamps_ns[camera_stamps_ns <= stamps_ns[-1]]
    return Drive(
        world=world,
        stamps_ns=trajectory.stamps_ns,
        T_map_base=trajectory.T_map_base,
        T_odom_base=T_odom_base,
        camera_stamps_ns=camera_stamps_ns,
        distance_m=trajectory.distance_m,
        trajectory=trajectory,
        plan=plan,
        t0_ns=t0_ns,
        seed=seed,
    )
