"""Routes that ride elevators: a planar route with stops in the cab, and the heights over time.

A waypoint ``ride: {elevator: NAME, to: FLOOR}`` becomes three planar stops (the shaft stands at
the same ``x, y`` on every floor, so the planar route of :mod:`tagloc.sim.trajectory` is planned
unchanged): the *landing*, ``LANDING_M`` in front of the door on the current floor, where the robot
calls the cab and waits until its door is open (the cab comes from where it is); the cab's centre,
where it stands for the ride (``dwell_s``, the door closing, the trip, the door opening; it faces
the wall opposite the door, having walked in, then turns in place to walk out); the landing of the
new floor (``EXIT_PAUSE_S`` there). The cab's door closes ``dwell_s`` after the robot walked in
and after it walked out. A later call on a cab whose door is still closing waits for it (the stop
at the landing grows until the door is open).

:class:`RidePlan` is a :class:`~tagloc.sim.trajectory.RoutePlan` whose :meth:`RidePlan.sample`
gives ``T_map_base`` its height: the floor's, or the cab's during a trip (then the base's z
velocity and acceleration are the cab's). Its functions of time (seconds after the route start)
tell each cab's pose and door, the robot's floor (None during a trip) and the cab it is in.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.config import FieldPathError
from tagloc.geometry import SE3
from tagloc.sim._motion import _merge_duplicates
from tagloc.sim.elevator import FLOOR_TOLERANCE_M, CabTimeline, DoorTimeline, ZTimeline, trapezoid
from tagloc.sim.floors import Floor, Shaft
from tagloc.sim.route import RouteConfig
from tagloc.sim.trajectory import RoutePlan, Trajectory, plan_route

__all__ = [
    "EXIT_PAUSE_S", "LANDING_M", "RidePlan", "RideTimes", "cab_contains", "landing_and_centre",
    "plan_rides",
]  # fmt: skip

#: The landing stop: this far in front of the cab's door, metres.
LANDING_M = 0.9
#: The robot stands this long at the landing after walking out of the cab, seconds.
EXIT_PAUSE_S = 0.5
#: Checkpoint name -> ``((x, y), floor name)``.
CheckpointTable = Mapping[str, tuple[tuple[float, float], str]]


@dataclass(frozen=True, slots=True)
class RideTimes:
    """One ride (seconds after the route start): the robot reaches the landing (``call_s``),
    the cab's centre (``enter_s``); the cab leaves (``depart_s``) and arrives (``arrive_s``);
    the robot is back at a landing (``exit_s``)."""

    elevator: str
    from_floor: str
    to_floor: str
    call_s: float
    enter_s: float
    depart_s: float
    arrive_s: float
    exit_s: float


@dataclass(frozen=True, slots=True)
class RidePlan(RoutePlan):
    """A route with rides (module docstring). Times are seconds after the route start."""

    robot_z: ZTimeline
    cabs: tuple[CabTimeline, ...]
    floor_names: tuple[str, ...]
    floor_heights: FloatArray
    rides: tuple[RideTimes, ...]

    def sample(self, stamps_ns: npt.NDArray[np.int64], t0_ns: int = 0) -> Trajectory:
        """:meth:`RoutePlan.sample` with the height: the floor's, or the cab's on a trip."""
        flat = RoutePlan.sample(self, stamps_ns, t0_ns)
        t = (np.asarray(stamps_ns, dtype=np.int64) - np.int64(t0_ns)).astype(np.float64) * 1e-9
        z, vz, az = self.robot_z.evaluate(np.clip(t, 0.0, self.total_duration_s))
        translation = np.array(flat.T_map_base.translation, dtype=np.float64).reshape(-1, 3)
        translation[:, 2] = z
        velocity, accel = flat.linear_velocity_base.copy(), flat.linear_acceleration_base.copy()
        velocity[:, 2], accel[:, 2] = vz, az
        for a in (translation, velocity, accel):
            a.flags.writeable = False
        T = SE3(rotation=flat.T_map_base.rotation, translation=translation)
        return replace(
            flat, T_map_base=T, linear_velocity_base=velocity, linear_acceleration_base=accel
        )

    def cab(self, elevator: str | None = None) -> CabTimeline:
        """The cab of shaft ``elevator`` (default: the first). Raises ``KeyError``."""
        if elevator is None:
            return self.cabs[0]
        for cab in self.cabs:
            if cab.name == elevator:
                return cab
        raise KeyError(f"no elevator {elevator!r} (known: {', '.join(c.name for c in self.cabs)})")

    def floor_at(self, t_s: npt.ArrayLike) -> list[str | None]:
        """The robot's floor at each ``t_s``: a floor's name, or None during a trip."""
        t = np.clip(t_s, 0.0, self.total_duration_s)
        z, moving = self.robot_z.z(t), self.robot_z.moving(t)
        return [None if m else self.floor_of(float(v)) for v, m in zip(z, moving, strict=True)]

    def floor_of(self, z: float) -> str | None:
        """The floor at height ``z`` (within a micrometre), or None."""
        k = int(np.argmin(np.abs(self.floor_heights - z)))
        return self.floor_names[k] if abs(self.floor_heights[k] - z) <= FLOOR_TOLERANCE_M else None

    def cab_floor_at(self, t_s: npt.ArrayLike, elevator: str | None = None) -> list[str | None]:
        """Where the cab stands at each ``t_s`` (a floor's name; None while it moves)."""
        z_line = self.cab(elevator).z
        z, moving = z_line.z(t_s), z_line.moving(t_s)
        return [None if m else self.floor_of(float(v)) for v, m in zip(z, moving, strict=True)]

    def cab_of(self, t_s: npt.ArrayLike, xy: FloatArray) -> list[str | None]:
        """The cab (its shaft's name) the robot, at planar ``xy`` (N, 2) at ``t_s`` (N,), is in."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        z = self.robot_z.z(np.clip(t, 0.0, self.total_duration_s))
        out: list[str | None] = [None] * len(t)
        for cab in self.cabs:
            inside = cab.contains(xy) & (np.abs(cab.z.z(t) - z) <= FLOOR_TOLERANCE_M)
            for i in np.flatnonzero(inside):
                out[int(i)] = out[int(i)] or cab.name
        return out


def cab_contains(shaft: Shaft, xy: FloatArray) -> bool:
    """Whether the planar point ``xy`` (1, 2) in ``map`` lies inside the shaft's footprint."""
    p = shaft.pose_in_map
    cab = CabTimeline(shaft.name, shaft.frame, (p.x, p.y, math.radians(p.yaw_deg)),
                      (shaft.footprint[0] / 2, shaft.footprint[1] / 2),
                      ZTimeline.from_rows(0.0, []), DoorTimeline.build([]))  # fmt: skip
    return bool(cab.contains(xy)[0])


def landing_and_centre(shaft: Shaft) -> tuple[tuple[float, float], tuple[float, float]]:
    """The landing stop in front of the door and the cab's centre, planar ``map`` points."""
    p = shaft.pose_in_map
    yaw = math.radians(p.yaw_deg)
    nx, ny = shaft.door_normal_cab()
    half = shaft.footprint[0] / 2 if nx else shaft.footprint[1] / 2
    out = half + LANDING_M
    lx, ly = nx * out, ny * out
    c, s = math.cos(yaw), math.sin(yaw)
    return (p.x + c * lx - s * ly, p.y + s * lx + c * ly), (p.x, p.y)


def plan_rides(
    route: RouteConfig,
    floors: Sequence[Floor],
    shafts: Sequence[Shaft],
    checkpoints: CheckpointTable,
) -> RidePlan:
    """Plan ``route`` through a building (see the module docstring).

    The robot starts on the floor of the first waypoint's checkpoint (``floors[0]`` for an
    ``[x, y]``).

    Raises
    ------
    FieldPathError
        At ``route.waypoints[j]`` for a checkpoint on another floor than the robot is on, an
        unknown elevator, a floor it does not serve, a ride to the floor the robot is on.
    ValueError
        Fewer than two distinct planar stops.
    """
    heights = {f.name: f.height_m for f in floors}
    by_name = {s.name: s for s in shafts}
    first = route.waypoints[0].at
    floor = checkpoints[first][1] if isinstance(first, str) else floors[0].name
    start_floor = floor
    cab_floor = {s.name: s.first_floor for s in shafts}
    points: list[tuple[float, float]] = []
    dwell: list[float] = []
    pending: list[tuple[Shaft, str, str, str, int]] = []  # shaft, cab from, from, to, stop index
    for _ in range(route.repeat):
        for j, wp in enumerate(route.waypoints):
            where = ("route", "waypoints", j)
            if wp.ride is None:
                if isinstance(wp.at, str):
                    xy, on = checkpoints[wp.at]
                    if on != floor:
                        raise FieldPathError(
                            where, f"checkpoint {wp.at!r} is on floor {on}, the robot on {floor}"
                        )
                else:
                    assert wp.at is not None
                    xy = wp.at
                points.append(xy)
                dwell.append(route.dwell if wp.dwell is None else wp.dwell)
                continue
            shaft = by_name.get(wp.ride.elevator)
            if shaft is None:
                known = ", ".join(by_name) or "none"
                raise FieldPathError((*where, "ride", "elevator"), f"no elevator "
                                     f"{wp.ride.elevator!r} (known: {known})")  # fmt: skip
            for name in (floor, wp.ride.to):
                if name not in shaft.floors:
                    raise FieldPathError(
                        (*where, "ride"), f"elevator {shaft.name} does not serve floor {name}"
                    )
            if wp.ride.to == floor:
                raise FieldPathError((*where, "ride", "to"), f"the robot is on floor {floor}")
            landing, centre = landing_and_centre(shaft)
            pending.append((shaft, cab_floor[shaft.name], floor, wp.ride.to, len(points)))
            points += [landing, centre, landing]
            trip = trapezoid(heights[wp.ride.to] - heights[floor], shaft.speed_mps,
                             shaft.accel_mps2)[2]  # fmt: skip
            call = shaft.door_open_s
            if cab_floor[shaft.name] != floor:
                call += trapezoid(heights[floor] - heights[cab_floor[shaft.name]],
                                  shaft.speed_mps, shaft.accel_mps2)[2]  # fmt: skip
            dwell += [call, shaft.dwell_s + shaft.door_close_s + trip + shaft.door_open_s,
                      EXIT_PAUSE_S]  # fmt: skip
            cab_floor[shaft.name], floor = wp.ride.to, wp.ride.to
    return _schedule(route, floors, shafts, start_floor, points, dwell, pending)


def _merged_index(points: list[tuple[float, float]]) -> list[int]:
    """Index of each point after consecutive duplicates are merged (as the planner does)."""
    out, k = [0], 0
    for a, b in itertools.pairwise(points):
        k += 0 if math.hypot(b[0] - a[0], b[1] - a[1]) < 1e-9 else 1
        out.append(k)
    return out


def _schedule(
    route: RouteConfig,
    floors: Sequence[Floor],
    shafts: Sequence[Shaft],
    start_floor: str,
    points: list[tuple[float, float]],
    dwell: list[float],
    pending: list[tuple[Shaft, str, str, str, int]],
) -> RidePlan:
    """Plan, then run each cab through its calls; a call answered late lengthens the robot's
    wait at the landing and the plan is made again (at most once per ride)."""
    heights = {f.name: f.height_m for f in floors}
    merged = _merged_index(points)
    for _ in range(len(pending) + 1):
        plan = plan_route(
            np.array(points, dtype=np.float64), dwell, speed=route.speed,
            accel_max=route.accel_max, yaw_rate_max=route.yaw_rate_max,
            yaw_accel_max=route.yaw_accel_max, corner_radius=route.corner_radius,
        )  # fmt: skip
        _, merged_dwell = _merge_duplicates(np.array(points, dtype=np.float64), np.array(dwell))
        times = plan.waypoint_times_s
        moves: dict[str, list[tuple[float, float, float]]] = {s.name: [] for s in shafts}
        doors: dict[str, list[tuple[float, float, bool]]] = {s.name: [] for s in shafts}
        free = {s.name: 0.0 for s in shafts}
        rides: list[RideTimes] = []
        late = None
        for shaft, cab_from, f_from, f_to, k in pending:
            name = shaft.name
            t_call, t_in, t_out = (float(times[merged[k + i]]) for i in range(3))
            t = max(t_call, free[name])
            if cab_from != f_from:
                moves[name].append((t, heights[cab_from], heights[f_from]))
                t += trapezoid(heights[f_from] - heights[cab_from], shaft.speed_mps,
                               shaft.accel_mps2)[2]  # fmt: skip
            doors[name].append((t, shaft.door_open_s, True))
            ready = t + shaft.door_open_s
            wait_end = t_call + float(merged_dwell[merged[k]])
            if ready > wait_end + 1e-9 and late is None:
                late = (k, ready - wait_end)
            depart = t_in + shaft.dwell_s + shaft.door_close_s
            doors[name].append((t_in + shaft.dwell_s, shaft.door_close_s, False))
            moves[name].append((depart, heights[f_from], heights[f_to]))
            arrive = depart + trapezoid(heights[f_to] - heights[f_from], shaft.speed_mps,
                                        shaft.accel_mps2)[2]  # fmt: skip
            doors[name].append((arrive, shaft.door_open_s, True))
            doors[name].append((t_out + shaft.dwell_s, shaft.door_close_s, False))
            free[name] = t_out + shaft.dwell_s + shaft.door_close_s
            rides.append(RideTimes(name, f_from, f_to, t_call, t_in, depart, arrive, t_out))
        if late is None:
            break
        dwell[late[0]] += late[1]
    ride_moves = [(r.depart_s, heights[r.from_floor], heights[r.to_floor]) for r in rides]
    speeds = {s.name: s for s in shafts}
    robot_rows = [
        (t, z0, z1, speeds[r.elevator].accel_mps2,
         *trapezoid(z1 - z0, speeds[r.elevator].speed_mps, speeds[r.elevator].accel_mps2))
        for r, (t, z0, z1) in zip(rides, ride_moves, strict=True)
    ]  # fmt: skip
    cabs = tuple(
        CabTimeline(
            s.name, s.frame,
            (s.pose_in_map.x, s.pose_in_map.y, math.radians(s.pose_in_map.yaw_deg)),
            (s.footprint[0] / 2, s.footprint[1] / 2),
            ZTimeline.build(heights[s.first_floor], moves[s.name], s.speed_mps, s.accel_mps2),
            DoorTimeline.build(doors[s.name]),
        )
        for s in shafts
    )  # fmt: skip
    fields = {f: getattr(plan, f) for f in RoutePlan.__dataclass_fields__}
    return RidePlan(
        **fields,
        robot_z=ZTimeline.from_rows(heights[start_floor], robot_rows),
        cabs=cabs,
        floor_names=tuple(f.name for f in floors),
        floor_heights=np.array([f.height_m for f in floors], dtype=np.float64),
        rides=tuple(rides),
    )
