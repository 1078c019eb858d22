"""Ground-truth trajectories of a planar robot driving a route of waypoints.

A route is planned once into a list of *pieces* (dwell, straight line, circular arc, turn in place);
each piece moves along a one-dimensional speed profile that ramps between speeds with a raised
cosine, ``v(t) = v0 + (v1 - v0) (1 - cos(pi t / T)) / 2``, so acceleration is continuous and
bounded by ``a_max`` when ``T = pi |v1 - v0| / (2 a_max)``; such a ramp covers
``pi |v1^2 - v0^2| / (4 a_max)``.
Corners are either rounded (a circular fillet driven at ``min(speed, yaw_rate_max * radius)``) or,
at waypoints with a dwell, sharp turns and reversals, stop points: arrive, dwell, turn in place with
the same raised-cosine profile on yaw. Corner speeds are made reachable by one forward and one
backward pass over the lines (as in time-optimal path parameterization). Sampling the plan at any
stamps is vectorized and exact (no interpolation).

Frames: ``base`` is the robot body frame (x forward, y left, z up) on the floor plane, so
``T_map_base`` has z = 0, roll = pitch = 0. Yaw is kept unwrapped (continuous).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, model_validator

from tagloc.geometry import SE3, SO3

FloatArray = NDArray[np.float64]

#: Turns sharper than this always stop and turn in place, even with ``corner_radius > 0``.
MAX_ROUNDED_TURN_RAD = math.radians(120.0)
DWELL, LINE, ARC, TURN = 0, 1, 2, 3


def _check_target(value: Any) -> Any:
    """Accept a checkpoint name or a finite ``[x, y]`` pair (as a tuple), else raise."""
    if isinstance(value, str):
        return value
    if (
        isinstance(value, list | tuple)
        and len(value) == 2
        and all(
            isinstance(c, int | float) and not isinstance(c, bool) and math.isfinite(c)
            for c in value
        )
    ):
        return (float(value[0]), float(value[1]))
    raise ValueError(f"expected a checkpoint name or [x, y] in metres, got {value!r}")


class Waypoint(BaseModel):
    """A route waypoint: ``at`` (checkpoint name or ``[x, y]`` in map), optional ``dwell`` (s)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    at: Annotated[str | tuple[float, float], BeforeValidator(_check_target)]
    dwell: float | None = Field(default=None, ge=0.0)

    @model_validator(mode="before")
    @classmethod
    def _bare(cls, data: Any) -> Any:
        return data if isinstance(data, dict) else {"at": data}


class RouteConfig(BaseModel):
    """The ``route`` section of a world file (units: m, s, rad; see the module docstring)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    waypoints: tuple[Waypoint, ...] = Field(min_length=2)
    speed: float = Field(gt=0.0, le=5.0)
    accel_max: float = Field(default=0.5, gt=0.0)
    yaw_rate_max: float = Field(default=0.8, gt=0.0, le=10.0)
    yaw_accel_max: float = Field(default=1.5, gt=0.0)
    corner_radius: float = Field(default=0.0, ge=0.0)
    dwell: float = Field(default=0.0, ge=0.0)
    repeat: int = Field(default=1, ge=1, le=100)


@dataclass(frozen=True, slots=True)
class Trajectory:
    """Ground truth sampled at ``stamps_ns`` (N samples).

    Attributes
    ----------
    stamps_ns : (N,) int64
        Sample times, nanoseconds.
    T_map_base : SE3 batch of N
        Pose of ``base`` in ``map`` (z = 0, level).
    xy_yaw_map_base : (N, 3) float
        The same poses as ``[x, y, yaw]`` (metres, radians, yaw unwrapped).
    linear_velocity_base, angular_velocity_base : (N, 3) float
        Body velocity of ``base`` relative to ``map``, expressed in ``base`` (m/s, rad/s).
    linear_acceleration_base : (N, 3) float
        Tangential (x) and centripetal (y) acceleration in ``base``, m/s^2 (no gravity).
    distance_m : (N,) float
        Path length travelled since the start of the route, metres.
    """

    stamps_ns: NDArray[np.int64]
    T_map_base: SE3
    xy_yaw_map_base: FloatArray
    linear_velocity_base: FloatArray
    angular_velocity_base: FloatArray
    linear_acceleration_base: FloatArray
    distance_m: FloatArray


@dataclass(frozen=True, slots=True)
class RoutePlan:
    """A planned route: P pieces with start times (s after the route start) and geometry.

    Attributes
    ----------
    kind : (P,) int  -- DWELL, LINE, ARC or TURN
    start_s, duration_s : (P,) float
    origin_xy_yaw : (P, 3) float  -- pose at the piece start, map frame
    sign : (P,) float  -- +1 left (counter-clockwise) / -1 right, for ARC and TURN
    radius, center_xy : (P,), (P, 2) float  -- ARC geometry (map frame)
    profile : (P, 6) float  -- ``[v0, v_peak, v1, T_ramp_up, T_cruise, T_ramp_down]``
    distance_start_m : (P,) float  -- path length before the piece
    waypoints_xy : (M, 2) float  -- the route's waypoints (consecutive duplicates merged)
    waypoint_times_s : (M,) float  -- when each is reached (arc middle for rounded corners)
    length_m : float  -- path length of the whole route
    """

    kind: NDArray[np.int64]
    start_s: FloatArray
    duration_s: FloatArray
    origin_xy_yaw: FloatArray
    sign: FloatArray
    radius: FloatArray
    center_xy: FloatArray
    profile: FloatArray
    distance_start_m: FloatArray
    waypoints_xy: FloatArray
    waypoint_times_s: FloatArray
    length_m: float

    @property
    def total_duration_s(self) -> float:
        """Duration of the whole route, seconds."""
        return float(self.start_s[-1] + self.duration_s[-1])

    def sample(self, stamps_ns: NDArray[np.int64], t0_ns: int = 0) -> Trajectory:
        """Evaluate the plan at ``stamps_ns`` (route starts at ``t0_ns``; clamped at both ends)."""
        stamps = np.asarray(stamps_ns, dtype=np.int64)
        t = (stamps - np.int64(t0_ns)).astype(np.float64) * 1e-9
        i = np.clip(np.searchsorted(self.start_s, t, side="right") - 1, 0, len(self.kind) - 1)
        tau = np.clip(t - self.start_s[i], 0.0, self.duration_s[i])
        s, v, a = _profile(tau, self.profile[i])
        kind, sign, x0, y0, yaw0 = (self.kind[i], self.sign[i], *self.origin_xy_yaw[i].T)
        radius = np.where(kind == ARC, self.radius[i], 1.0)
        phi = np.select([kind == ARC, kind == TURN], [s / radius, s], 0.0) * sign
        alpha = np.arctan2(y0 - self.center_xy[i, 1], x0 - self.center_xy[i, 0]) + phi
        arc_xy = self.center_xy[i] + radius[:, None] * np.stack([np.cos(alpha), np.sin(alpha)], 1)
        line_xy = np.stack([x0 + s * np.cos(yaw0), y0 + s * np.sin(yaw0)], axis=1)
        xy = np.where(
            (kind == ARC)[:, None],
            arc_xy,
            np.where((kind == LINE)[:, None], line_xy, np.stack([x0, y0], 1)),
        )
        xy_yaw = np.column_stack([xy, yaw0 + phi])
        translating = (kind == LINE) | (kind == ARC)
        zeros = np.zeros_like(t)
        omega = np.select([kind == ARC, kind == TURN], [sign * v / radius, sign * v], 0.0)
        lin_vel = np.column_stack([np.where(translating, v, 0.0), zeros, zeros])
        lin_acc = np.column_stack(
            [np.where(translating, a, 0.0), np.where(kind == ARC, omega * v, 0.0), zeros]
        )
        distance = self.distance_start_m[i] + np.where(translating, s, 0.0)
        return Trajectory(
            stamps_ns=_readonly(stamps.copy()),
            T_map_base=se3_from_xy_yaw(xy_yaw),
            xy_yaw_map_base=_readonly(xy_yaw),
            linear_velocity_base=_readonly(lin_vel),
            angular_velocity_base=_readonly(np.column_stack([zeros, zeros, omega])),
            linear_acceleration_base=_readonly(lin_acc),
            distance_m=_readonly(distance),
        )


def route_points(
    route: RouteConfig, checkpoints_xy: Mapping[str, tuple[float, float]]
) -> tuple[FloatArray, FloatArray]:
    """Resolve a route into ``(points_xy (M, 2), dwell_s (M,))``, repeated ``route.repeat`` times.

    Raises
    ------
    KeyError
        A waypoint names a checkpoint missing from ``checkpoints_xy`` (the world validates this).
    """
    xy = [checkpoints_xy[w.at] if isinstance(w.at, str) else w.at for w in route.waypoints]
    dwell = [route.dwell if w.dwell is None else w.dwell for w in route.waypoints]
    return np.array(xy * route.repeat, dtype=np.float64), np.array(dwell * route.repeat)


def plan_route(
    points_xy: FloatArray,
    dwell_s: Sequence[float] | FloatArray,
    *,
    speed: float,
    accel_max: float,
    yaw_rate_max: float,
    yaw_accel_max: float,
    corner_radius: float = 0.0,
) -> RoutePlan:
    """Plan a drive through ``points_xy`` (map frame), starting at rest facing the first segment.

    Consecutive duplicate points are merged (keeping the longer dwell). A corner is rounded when
    ``corner_radius > 0``, its dwell is 0 and it turns by at most ``MAX_ROUNDED_TURN_RAD``; the
    fillet radius shrinks to fit half of the shorter adjacent segment. Exact reversals turn the
    way that unwinds the accumulated heading (ties: left), so out-and-back excursions do not wind
    up turns. Fillets step the yaw rate from 0 to ``v / r`` (bounded rate, no clothoid).

    Parameters
    ----------
    points_xy : (M, 2) float
        Waypoints in ``map``, metres; at least two distinct.
    dwell_s : (M,) float
        Seconds to stand still at each waypoint.
    speed, accel_max, yaw_rate_max, yaw_accel_max, corner_radius : float
        m/s, m/s^2, rad/s, rad/s^2, m.

    Raises
    ------
    ValueError
        Fewer than two distinct waypoints.
    """
    pts, dwell = _merge_duplicates(np.asarray(points_xy, dtype=np.float64), np.asarray(dwell_s))
    if len(pts) < 2:
        raise ValueError("a route needs at least two distinct waypoints")
    seg = np.diff(pts, axis=0)
    seg_len = np.hypot(seg[:, 0], seg[:, 1])
    heading = np.arctan2(seg[:, 1], seg[:, 0])
    turn = np.zeros(len(pts))
    turn[1:-1] = (np.diff(heading) + np.pi) % (2 * np.pi) - np.pi
    cum = heading[0]
    for k in range(1, len(pts) - 1):  # unwind exact reversals; keep the heading continuous
        if abs(abs(turn[k]) - np.pi) < 1e-9:
            turn[k] = -np.pi if cum > heading[0] + 1e-9 else np.pi
        cum += turn[k]
    rounded = (corner_radius > 0) & (dwell == 0) & (np.abs(turn) <= MAX_ROUNDED_TURN_RAD)
    rounded[[0, -1]] = False
    half = np.tan(np.abs(turn) / 2)
    shorter = np.minimum(np.r_[np.inf, seg_len], np.r_[seg_len, np.inf])
    radius = np.where(
        rounded, np.minimum(corner_radius, 0.5 * shorter / np.maximum(half, 1e-12)), 0
    )
    tangent = radius * half
    corner_v = np.where(
        rounded, np.minimum(speed, yaw_rate_max * np.where(turn == 0, np.inf, radius)), 0.0
    )
    line_len = seg_len - tangent[:-1] - tangent[1:]
    for k in range(len(line_len)):  # forward pass: reachable from the previous corner
        corner_v[k + 1] = min(
            corner_v[k + 1], math.sqrt(corner_v[k] ** 2 + _reach(line_len[k], accel_max))
        )
    for k in reversed(range(len(line_len))):  # backward pass: able to slow down for the next
        corner_v[k] = min(
            corner_v[k], math.sqrt(corner_v[k + 1] ** 2 + _reach(line_len[k], accel_max))
        )
    builder = _PieceBuilder(pts[0], heading[0])
    times = np.zeros(len(pts))
    for k in range(len(pts)):
        if k > 0:
            builder.line(line_len[k - 1], corner_v[k - 1], corner_v[k], speed, accel_max)
        if rounded[k]:
            times[k] = builder.arc(radius[k], turn[k], corner_v[k])
            continue
        times[k] = builder.clock
        builder.dwell(dwell[k])
        if k < len(pts) - 1 and turn[k] != 0.0:
            builder.turn(turn[k], yaw_rate_max, yaw_accel_max)
    return builder.finish(pts, times)


def plan_from_config(
    route: RouteConfig, checkpoints_xy: Mapping[str, tuple[float, float]]
) -> RoutePlan:
    """:func:`plan_route` with the arguments unpacked from a :class:`RouteConfig`."""
    points_xy, dwell_s = route_points(route, checkpoints_xy)
    return plan_route(
        points_xy,
        dwell_s,
        speed=route.speed,
        accel_max=route.accel_max,
        yaw_rate_max=route.yaw_rate_max,
        yaw_accel_max=route.yaw_accel_max,
        corner_radius=route.corner_radius,
    )


def regular_stamps(duration_s: float, rate_hz: float, t0_ns: int = 0) -> NDArray[np.int64]:
    """(N,) int64 stamps every ``round(1e9 / rate_hz)`` ns from ``t0_ns``, to ``duration_s``."""
    period_ns = round(1e9 / rate_hz)
    count = math.ceil(round(duration_s * 1e9) / period_ns) + 1
    return np.int64(t0_ns) + np.arange(count, dtype=np.int64) * np.int64(period_ns)


def generate_trajectory(plan: RoutePlan, rate_hz: float, t0_ns: int = 0) -> Trajectory:
    """Sample ``plan`` at ``rate_hz`` from ``t0_ns`` to the end of the route (inclusive)."""
    return plan.sample(regular_stamps(plan.total_duration_s, rate_hz, t0_ns), t0_ns)


def se3_from_xy_yaw(xy_yaw: FloatArray) -> SE3:
    """Planar poses ``(N, 3)`` ``[x, y, yaw]`` as an SE3 batch (z = 0, level)."""
    c, s = np.cos(xy_yaw[:, 2]), np.sin(xy_yaw[:, 2])
    R = np.zeros((len(xy_yaw), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    t = np.column_stack([xy_yaw[:, :2], np.zeros(len(xy_yaw))])
    return SE3(rotation=SO3.from_matrix(R), translation=t)


class _PieceBuilder:
    """Appends pieces while tracking the clock, the pose and the distance travelled."""

    def __init__(self, xy: FloatArray, yaw: float) -> None:
        self.rows: list[tuple[float, ...]] = []
        self.clock, self.dist, self.pose = 0.0, 0.0, np.array([xy[0], xy[1], yaw])

    def _add(
        self,
        kind: int,
        duration: float,
        profile: Sequence[float],
        length: float,
        end_pose: FloatArray,
        sign: float = 1.0,
        radius: float = 0.0,
        center: Sequence[float] = (0.0, 0.0),
    ) -> None:
        """Append a row: kind, start, duration, x, y, yaw, sign, radius, cx, cy, profile, dist."""
        row = (kind, self.clock, duration, *self.pose, sign, radius, *center, *profile, self.dist)
        self.rows.append(row)
        self.clock, self.dist, self.pose = self.clock + duration, self.dist + length, end_pose

    def dwell(self, seconds: float) -> None:
        if seconds > 0:
            self._add(DWELL, seconds, (0, 0, 0, 0, seconds, 0), 0.0, self.pose)

    def line(self, length: float, v0: float, v1: float, v_max: float, a_max: float) -> None:
        if length <= 1e-12:
            return
        profile = _ramp_profile(length, v0, v1, v_max, a_max)
        c, s = math.cos(self.pose[2]), math.sin(self.pose[2])
        end = self.pose + np.array([length * c, length * s, 0.0])
        self._add(LINE, profile[3] + profile[4] + profile[5], profile, length, end)

    def turn(self, angle: float, rate_max: float, accel_max: float) -> None:
        profile = _ramp_profile(abs(angle), 0.0, 0.0, rate_max, accel_max)
        end = self.pose + np.array([0.0, 0.0, angle])
        self._add(
            TURN, profile[3] + profile[4] + profile[5], profile, 0.0, end, math.copysign(1.0, angle)
        )

    def arc(self, radius: float, angle: float, v: float) -> float:
        """Append a fillet; return the time its middle is reached."""
        if radius <= 0 or angle == 0.0:
            return self.clock
        sign = math.copysign(1.0, angle)
        x, y, yaw = self.pose
        center = (x - sign * radius * math.sin(yaw), y + sign * radius * math.cos(yaw))
        alpha = math.atan2(y - center[1], x - center[0]) + angle
        end = np.array(
            [
                center[0] + radius * math.cos(alpha),
                center[1] + radius * math.sin(alpha),
                yaw + angle,
            ]
        )
        duration = radius * abs(angle) / v
        self._add(
            ARC, duration, (v, v, v, 0, duration, 0), radius * abs(angle), end, sign, radius, center
        )
        return self.clock - duration / 2

    def finish(self, waypoints_xy: FloatArray, times: FloatArray) -> RoutePlan:
        table = np.array(self.rows, dtype=np.float64)
        col = [_readonly(np.ascontiguousarray(c)) for c in table.T]
        return RoutePlan(
            kind=_readonly(table[:, 0].astype(np.int64)),
            start_s=col[1],
            duration_s=col[2],
            origin_xy_yaw=_readonly(table[:, 3:6].copy()),
            sign=col[6],
            radius=col[7],
            center_xy=_readonly(table[:, 8:10].copy()),
            profile=_readonly(table[:, 10:16].copy()),
            distance_start_m=col[16],
            waypoints_xy=_readonly(waypoints_xy.copy()),
            waypoint_times_s=_readonly(times),
            length_m=self.dist,
        )


def _reach(length: float, accel_max: float) -> float:
    """Largest change of ``v^2`` a raised-cosine ramp achieves over ``length``."""
    return 4.0 * accel_max * max(length, 0.0) / math.pi


def _ramp_profile(length: float, v0: float, v1: float, v_max: float, a_max: float) -> list[float]:
    """``[v0, v_peak, v1, T_up, T_cruise, T_down]`` covering ``length`` (v0, v1 reachable)."""
    v_peak = min(v_max, math.sqrt((_reach(length, a_max) + v0**2 + v1**2) / 2.0))
    v_peak = max(v_peak, v0, v1)
    t_up, t_down = math.pi * (v_peak - v0) / (2 * a_max), math.pi * (v_peak - v1) / (2 * a_max)
    ramps = 0.5 * (v0 + v_peak) * t_up + 0.5 * (v_peak + v1) * t_down
    return [v0, v_peak, v1, t_up, max(length - ramps, 0.0) / v_peak, t_down]


def _profile(tau: FloatArray, p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Distance, speed and acceleration ``tau`` seconds into pieces with profiles ``p`` (N, 6)."""
    v0, vp, v1, t_up, t_cruise, t_down = p.T
    out = []
    for t_ramp, start, v_from, v_to in ((t_up, 0.0, v0, vp), (t_down, t_up + t_cruise, vp, v1)):
        safe = np.where(t_ramp > 0, t_ramp, 1.0)
        u = np.clip(tau - start, 0.0, t_ramp)
        w, dv = np.pi * u / safe, v_to - v_from
        out.append(
            (
                v_from * u + 0.5 * dv * (u - safe / np.pi * np.sin(w)),
                v_from + 0.5 * dv * (1 - np.cos(w)),
                0.5 * dv * np.pi / safe * np.sin(w),
            )
        )
    (s_up, v_up, a_up), (s_down, v_down, a_down) = out
    s = s_up + vp * np.clip(tau - t_up, 0.0, t_cruise) + s_down
    phase = [tau < t_up, tau < t_up + t_cruise]
    return s, np.select(phase, [v_up, vp], v_down), np.select(phase, [a_up, 0.0], a_down)


def _merge_duplicates(pts: FloatArray, dwell: FloatArray) -> tuple[FloatArray, FloatArray]:
    keep_pts, keep_dwell = [pts[0]], [float(dwell[0])]
    for p, d in zip(pts[1:], dwell[1:], strict=True):
        if np.hypot(*(p - keep_pts[-1])) < 1e-9:
            keep_dwell[-1] = max(keep_dwell[-1], float(d))
        else:
            keep_pts.append(p)
            keep_dwell.append(float(d))
    return np.array(keep_pts), np.array(keep_dwell)


def _readonly(array: NDArray[Any]) -> NDArray[Any]:
    array.flags.writeable = False
    return array
