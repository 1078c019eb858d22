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

import numpy as np
from numpy.typing import NDArray

from tagloc._types import FloatArray
from tagloc.geometry import SE3, SO3
from tagloc.sim._motion import (
    ARC,
    LINE,
    MAX_ROUNDED_TURN_RAD,
    TURN,
    _merge_duplicates,
    _PieceBuilder,
    _profile,
    _reach,
    _readonly,
)
from tagloc.sim.route import RouteConfig, route_points


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
    return RoutePlan(**builder.finish(pts, times))


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
