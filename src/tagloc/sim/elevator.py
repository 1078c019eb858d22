"""What an elevator cab does over time: its height (trapezoidal moves) and its doors.

Pure functions of time ``t_s`` (seconds after the route start, arrays), built once per drive by
:mod:`tagloc.sim.ride` from the route's rides:

- :class:`ZTimeline`: a height that stands still except during moves; move ``k`` starts at
  ``start_s[k]`` from ``z_from[k]`` to ``z_to[k]`` with a trapezoidal speed profile: constant
  acceleration ``accel`` up to ``v_peak`` (``<= speed``), cruise, the same deceleration (a triangle,
  ``v_peak = sqrt(|dz| accel)``, when the trip is too short to reach ``speed``). Position, speed and
  acceleration are exact (acceleration is piecewise constant: ``+-accel`` or 0).
- :class:`DoorTimeline`: the door's opening fraction (0 closed, 1 open), linear in time during each
  opening (``door_open_s``) or closing (``door_close_s``); closed before the first event. The door
  *is open* (:meth:`DoorTimeline.is_open`, the building's door signal and what sight lines and
  lidar beams see) from half-way through an opening to half-way through the next closing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3, SO3

__all__ = ["CabTimeline", "DoorTimeline", "ZTimeline", "trapezoid"]

#: Heights this close (m) are the same floor.
FLOOR_TOLERANCE_M = 1e-6


def trapezoid(distance_m: float, speed: float, accel: float) -> tuple[float, float, float]:
    """``(v_peak, t_accel, duration)`` of a rest-to-rest move over ``|distance_m|``."""
    d = abs(distance_m)
    if d * accel >= speed**2:
        return speed, speed / accel, speed / accel + d / speed
    v_peak = math.sqrt(d * accel)
    return v_peak, v_peak / accel, 2.0 * v_peak / accel


@dataclass(frozen=True, slots=True)
class ZTimeline:
    """A height over time (see the module docstring): ``z0`` before the first move; moves sorted
    by start and not overlapping."""

    z0: float
    start_s: FloatArray
    z_from: FloatArray
    z_to: FloatArray
    accel: FloatArray
    v_peak: FloatArray
    t_accel: FloatArray
    duration_s: FloatArray

    @classmethod
    def build(
        cls, z0: float, moves: list[tuple[float, float, float]], speed: float, accel: float
    ) -> ZTimeline:
        """From ``moves`` ``(start_s, z_from, z_to)`` of a cab with this ``speed``, ``accel``."""
        profiles = [trapezoid(z1 - z0_, speed, accel) for _, z0_, z1 in moves]
        return cls.from_rows(z0, [(*m, accel, *p) for m, p in zip(moves, profiles, strict=True)])

    @classmethod
    def from_rows(cls, z0: float, rows: Sequence[Sequence[float]]) -> ZTimeline:
        """From rows ``(start_s, z_from, z_to, accel, v_peak, t_accel, duration_s)``."""
        table = np.array(rows, dtype=np.float64).reshape(-1, 7)
        order = np.argsort(table[:, 0], kind="stable")
        cols = [np.ascontiguousarray(c) for c in table[order].T]
        return cls(z0, *cols)

    def _phase(self, t_s: npt.ArrayLike) -> tuple[FloatArray, npt.NDArray[np.intp], FloatArray]:
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        k = np.searchsorted(self.start_s, t, side="right") - 1
        kc = np.clip(k, 0, max(len(self.start_s) - 1, 0))
        tau = t - self.start_s[kc] if len(self.start_s) else np.zeros_like(t)
        return t, k, tau

    def evaluate(self, t_s: npt.ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(z, vz, az)`` at ``t_s`` (m, m/s, m/s^2)."""
        t, k, tau = self._phase(t_s)
        z, v, a = np.full_like(t, self.z0), np.zeros_like(t), np.zeros_like(t)
        if not len(self.start_s):
            return z, v, a
        kc = np.clip(k, 0, len(self.start_s) - 1)
        z0, z1, acc = self.z_from[kc], self.z_to[kc], self.accel[kc]
        vp, ta, T = self.v_peak[kc], self.t_accel[kc], self.duration_s[kc]
        sign = np.sign(z1 - z0)
        u = np.clip(tau, 0.0, T)
        s = np.select(
            [u < ta, u < T - ta],
            [0.5 * acc * u**2, 0.5 * acc * ta**2 + vp * (u - ta)],
            np.abs(z1 - z0) - 0.5 * acc * (T - u) ** 2,
        )
        moving = (k >= 0) & (tau < T)
        speed = np.select([u < ta, u < T - ta], [acc * u, vp], acc * (T - u))
        accel = np.select([u < ta, u < T - ta], [acc, 0.0], -acc)
        z = np.where(k >= 0, z0 + sign * s, self.z0)
        return z, np.where(moving, sign * speed, 0.0), np.where(moving, sign * accel, 0.0)

    def z(self, t_s: npt.ArrayLike) -> FloatArray:
        """Height at ``t_s``, m."""
        return self.evaluate(t_s)[0]

    def moving(self, t_s: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Strictly inside a move (not at its start or end)."""
        t, k, tau = self._phase(t_s)
        if not len(self.start_s):
            return np.zeros(len(t), dtype=bool)
        T = self.duration_s[np.clip(k, 0, len(self.start_s) - 1)]
        return np.asarray((k >= 0) & (tau > 0.0) & (tau < T))


@dataclass(frozen=True, slots=True)
class DoorTimeline:
    """A door over time (see the module docstring): events ``(start_s, duration_s, opening)``
    sorted by start."""

    start_s: FloatArray
    duration_s: FloatArray
    opening: npt.NDArray[np.bool_]

    @classmethod
    def build(cls, events: list[tuple[float, float, bool]]) -> DoorTimeline:
        rows = sorted(events, key=lambda e: e[0])
        return cls(
            np.array([r[0] for r in rows], dtype=np.float64),
            np.array([r[1] for r in rows], dtype=np.float64),
            np.array([r[2] for r in rows], dtype=bool),
        )

    def fraction(self, t_s: npt.ArrayLike) -> FloatArray:
        """How far open the door is at ``t_s``: 0 closed ... 1 open."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        if not len(self.start_s):
            return np.zeros_like(t)
        k = np.searchsorted(self.start_s, t, side="right") - 1
        kc = np.clip(k, 0, len(self.start_s) - 1)
        dur = self.duration_s[kc]
        safe = np.where(dur > 0, dur, 1.0)
        done = np.where(dur > 0, np.clip((t - self.start_s[kc]) / safe, 0.0, 1.0), 1.0)
        frac = np.where(self.opening[kc], done, 1.0 - done)
        return np.where(k >= 0, frac, 0.0)

    def is_open(self, t_s: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """Open at ``t_s`` (at least half-way: see the module docstring)."""
        return np.asarray(self.fraction(t_s) >= 0.5)


@dataclass(frozen=True, slots=True)
class CabTimeline:
    """One cab over a drive: its shaft's ``name`` and ``frame``, planar pose ``(x, y, yaw)`` of the
    cab frame in ``map``, height and doors."""

    name: str
    frame: str
    xy_yaw: tuple[float, float, float]
    half_size: tuple[float, float]
    z: ZTimeline
    doors: DoorTimeline

    def contains(self, xy: FloatArray) -> npt.NDArray[np.bool_]:
        """Whether planar points ``(N, 2)`` in ``map`` lie inside the cab's footprint."""
        x, y, yaw = self.xy_yaw
        d = np.atleast_2d(np.asarray(xy, dtype=np.float64)) - np.array([x, y])
        c, s = math.cos(yaw), math.sin(yaw)
        local = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]])
        return np.asarray((np.abs(local) <= np.array(self.half_size)).all(axis=1))

    def T_map_cab(self, t_s: float) -> SE3:
        """Pose of the cab frame in ``map`` at ``t_s`` (level; z = the cab floor's height)."""
        x, y, yaw = self.xy_yaw
        c, s = math.cos(yaw), math.sin(yaw)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        z = float(self.z.z(t_s)[0])
        return SE3(rotation=SO3.from_matrix(R), translation=np.array([x, y, z]))
