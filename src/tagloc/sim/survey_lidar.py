"""Lidar sweeps of a simulated survey drive, as a recorder keeps them.

A 10 Hz scanner gives 7 000 sweeps over the office's 12-minute survey; the map builder uses one
per ``keyframe_distance_m`` of travel. So the survey keeps, like a bag recorder decimating on the
robot's odometry, the first sweep and then each one that starts at least ``keep_distance_m`` of
odometry (or ``keep_turn_deg`` of its yaw) after the last kept one, simulated in the world by
:class:`tagloc.sim.lidar.LidarSimulator` (raw: skewed by the motion during the sweep, with time
offsets; range noise; no people).

A world without ``robot.lidar`` is surveyed with :data:`SURVEY_LIDAR`: the simulator's default
scanner (16 rings, -7 to 52 degrees, 360 degrees at 10 Hz, 2 cm range noise) 0.5 m above
``base``, level, looking forward.
"""

from __future__ import annotations

import numpy as np

from tagloc.mapping.survey_scans import SurveyScans, select_sweeps
from tagloc.sim.drive import Drive
from tagloc.sim.lidar import LidarSimulator
from tagloc.sim.robot import LidarConfig, LidarMount

#: The scanner of a survey in a world whose robot has none.
SURVEY_LIDAR = LidarConfig(
    T_base_lidar=LidarMount(position=(0.0, 0.0, 0.5), rpy_deg=(0.0, 0.0, 0.0))
)


def survey_scans_of(
    drive: Drive,
    keep_distance_m: float = 0.5,
    keep_turn_deg: float = 10.0,
    lidar: LidarConfig | None = None,
) -> SurveyScans:
    """The sweeps a survey of ``drive`` keeps (module docstring).

    Parameters
    ----------
    drive : Drive
    keep_distance_m, keep_turn_deg : float
        Keep a sweep after this much odometry travel or yaw since the last kept one.
    lidar : LidarConfig, optional
        Default: the world's ``robot.lidar``, else :data:`SURVEY_LIDAR`.
    """
    config = lidar or drive.world.robot.lidar or SURVEY_LIDAR
    simulator = LidarSimulator(config, drive.world.walls_in_map(), (), drive.t0_ns)
    starts = simulator.sweep_starts_ns(int(drive.stamps_ns[0]), int(drive.stamps_ns[-1]))
    # the odometry at each sweep start (nearest sample: the recorder's view)
    nearest = np.clip(np.searchsorted(drive.stamps_ns, starts), 0, len(drive.stamps_ns) - 1)
    T_odom = drive.T_odom_base[nearest]
    R = T_odom.rotation.as_matrix()
    yaw = np.arctan2(R[:, 1, 0], R[:, 0, 0])
    keep = select_sweeps(np.asarray(T_odom.translation), yaw, keep_distance_m,
                         np.radians(keep_turn_deg))  # fmt: skip

    def xy_yaw_at(stamps_ns: np.ndarray) -> np.ndarray:
        return np.asarray(drive.ground_truth_at(stamps_ns).xy_yaw_map_base)

    sweeps = [simulator.sweep(xy_yaw_at, int(starts[i]), int(i)).msg for i in keep]
    return SurveyScans(
        stamps_ns=starts[keep],
        points_lidar=tuple(m.points for m in sweeps),
        time_offset_s=tuple(m.time_offset_s for m in sweeps),
        T_base_lidar=simulator.T_base_lidar,
    )
