"""A simulated drive: ground truth along the world's route and the robot's drifting odometry.

Pure: no file I/O, no global state; the same world and seed give the same drive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from tagloc.geometry import SE3
from tagloc.sim.odometry import simulate_odometry
from tagloc.sim.trajectory import RoutePlan, Trajectory, plan_from_config, regular_stamps
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
    plan = plan_from_config(world.route, world.checkpoints_xy())
    stamps_ns = regular_stamps(plan.total_duration_s, robot.odom_rate_hz, t0_ns)
    trajectory = plan.sample(stamps_ns, t0_ns)
    # 2. corrupt the relative motions and integrate them into odometry
    T_odom_base = simulate_odometry(robot.odometry, trajectory.xy_yaw_map_base, seed)
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
