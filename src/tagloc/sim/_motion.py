"""Motion primitives of the route planner: pieces and their raised-cosine speed profiles."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tagloc._types import FloatArray

#: Turns sharper than this always stop and turn in place, even with ``corner_radius > 0``.
MAX_ROUNDED_TURN_RAD = math.radians(120.0)
DWELL, LINE, ARC, TURN = 0, 1, 2, 3


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

    def finish(self, waypoints_xy: FloatArray, times: FloatArray) -> dict[str, Any]:
        """The fields of a ``RoutePlan`` for the pieces added so far (read-only arrays)."""
        table = np.array(self.rows, dtype=np.float64)
        col = [_readonly(np.ascontiguousarray(c)) for c in table.T]
        return dict(
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
