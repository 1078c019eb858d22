"""The simulated lidar: sweeps of a spinning multi-ring scanner along a drive, as a driver
publishes them.

:class:`LidarSimulator` casts the beams of :class:`~tagloc.sim.robot.LidarConfig` into the world
(:mod:`tagloc.sim.lidar_cast`: walls of their material, the elevator cab's walls, the floor,
people). Sweep ``k`` starts at ``t0 + k / rate_hz``; column ``c`` fires ``column_offsets_s()[c]``
later from the scanner's *true* pose at that instant (the robot moves during the sweep). Each
point is expressed in the scanner frame at the time it was measured (raw, skewed: what a real
driver publishes; consumers de-skew with ``tagloc.lidar.cloud.deskew``) and carries its
``time_offset_s``. Beams without a return (nothing within range, glass, a lost reflection) are
left out, as drivers do.

Intensity by what returned: wall 100, floor 60, person 40, seen in a mirror 80, glass 10 (a weak
return); not a physical model.

Noise: the measured range is the true one plus ``N(0, range_sigma_m)``; sweep ``k`` draws from
``numpy.random.default_rng([seed, k])``, so any sweep can be simulated alone.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.geometry import SE3, SO3
from tagloc.lidar.voxel_stream import VoxelCentroids
from tagloc.messages import PointCloudMsg
from tagloc.sim.lidar_cast import (
    HIT_FLOOR,
    HIT_GLASS,
    HIT_PERSON,
    HIT_WALL,
    CastResult,
    Cylinders,
    Segments,
    cast_rays,
)
from tagloc.sim.people import Person, people_xy
from tagloc.sim.robot import LidarConfig
from tagloc.sim.world import Wall, World
from tagloc.units import S_NS

__all__ = ["LIDAR_FRAME", "LidarSimulator", "Sweep", "premap_from_world"]

LIDAR_FRAME = "lidar"
#: ``xy_yaw_at(stamps_ns) -> (K, 3)``: the base's true planar pose in ``map`` (``x, y, yaw``).
PoseFunction = Callable[[npt.NDArray[np.int64]], FloatArray]
_INTENSITY = {HIT_WALL: 100.0, HIT_FLOOR: 60.0, HIT_PERSON: 40.0, HIT_GLASS: 10.0}
_MIRRORED_INTENSITY = 80.0
_KNOTS = 11  # true poses sampled per sweep


@dataclass(frozen=True, slots=True)
class Sweep:
    """One simulated sweep with its truth (beams in firing order: column by column, rings low
    to high within a column).

    Attributes
    ----------
    msg : PointCloudMsg
        What the driver publishes (returns only).
    cast : CastResult
        Every beam's true result (``range_m`` before noise, ``kind``, ``bounces``, ``hit_map``).
    beam_index : (N,) int
        The beam of each row of ``msg.points``.
    R_map_lidar, t_map_lidar : (C, 3, 3), (C, 3) float
        The scanner's true pose when each column fired (see :attr:`T_map_lidar`).
    end_ns : int
        When the sweep ends: its last column fires (a driver publishes the sweep once its last
        point is measured, ``msg.last_point_ns()``, which is this unless that column returned
        nothing).
    """

    msg: PointCloudMsg
    cast: CastResult
    beam_index: npt.NDArray[np.intp]
    R_map_lidar: FloatArray
    t_map_lidar: FloatArray
    end_ns: int

    @property
    def T_map_lidar(self) -> SE3:
        """The scanner's true pose when each column fired (a batch of C)."""
        return SE3(rotation=SO3.from_matrix(self.R_map_lidar), translation=self.t_map_lidar)


class LidarSimulator:
    """Sweeps of ``config``'s scanner in ``world`` (walls, cab walls and ``people``).

    Parameters
    ----------
    config : LidarConfig
    walls : sequence of Wall
        ``world.walls_in_map()``.
    people : sequence of Person
        Moving occluders; their times are seconds after ``t0_ns``.
    t0_ns : int
        The route start (people's time origin).
    """

    def __init__(
        self,
        config: LidarConfig,
        walls: Sequence[Wall],
        people: Sequence[Person] = (),
        t0_ns: int = 0,
    ) -> None:
        self.config = config
        self.segments = Segments.from_walls(walls)
        self.people = tuple(people)
        self._people_wp = [p.waypoints() for p in self.people]
        self._radius = np.array([p.radius_m for p in self.people], dtype=np.float64)
        self._height = np.array([p.height_m for p in self.people], dtype=np.float64)
        self.t0_ns = t0_ns
        self.T_base_lidar = config.T_base_lidar.T_base_lidar()
        el, az = config.elevations_rad(), config.azimuths_rad()
        ce = np.cos(el)
        # (columns, rings, 3) unit beam directions in the scanner frame
        self.directions_lidar = np.stack(
            [
                np.cos(az)[:, None] * ce,
                np.sin(az)[:, None] * ce,
                np.broadcast_to(np.sin(el), (len(az), len(el))),
            ],
            axis=-1,
        )
        self.column_offsets_s = config.column_offsets_s()
        # a level scanner (z axis up) keeps each column's rings on one vertical plane
        self._level = bool(abs(self.T_base_lidar.rotation.matrix[2, 2] - 1.0) < 1e-12)

    @property
    def period_ns(self) -> int:
        """One sweep, ns (rounded)."""
        return round(S_NS / self.config.rate_hz)

    def sweep_starts_ns(self, t_begin_ns: int, t_end_ns: int) -> npt.NDArray[np.int64]:
        """Starts of the sweeps that begin at or after ``t_begin_ns`` and end by ``t_end_ns``."""
        period = self.period_ns
        n = max(0, (t_end_ns - t_begin_ns) // period)
        return t_begin_ns + period * np.arange(n, dtype=np.int64)

    def sweep(self, xy_yaw_at: PoseFunction, start_ns: int, index: int) -> Sweep:
        """Simulate the sweep starting at ``start_ns`` (its noise drawn from ``(seed, index)``).

        ``xy_yaw_at`` gives the base's true planar pose (``drive.ground_truth_at(stamps)
        .xy_yaw_map_base`` for a drive).
        """
        cfg = self.config
        columns, rings = self.directions_lidar.shape[:2]
        stamps = start_ns + np.round(self.column_offsets_s * S_NS).astype(np.int64)
        R, origins_c = self._column_poses(xy_yaw_at, stamps)
        origins = np.repeat(origins_c, rings, axis=0)
        directions = np.matmul(self.directions_lidar, R.transpose(0, 2, 1)).reshape(-1, 3)
        rng = np.random.default_rng([cfg.seed, index])
        noise = rng.normal(0.0, cfg.range_sigma_m, columns * rings) if cfg.range_sigma_m else 0.0
        glass = None
        if cfg.glass_return_probability > 0:
            glass = rng.random(columns * rings) < cfg.glass_return_probability
        cylinders = None
        if self.people:
            t_s = ((stamps - self.t0_ns) * 1e-9).astype(np.float64)
            centre = np.repeat(people_xy(self._people_wp, t_s), rings, axis=0)
            cylinders = Cylinders(centre, self._radius, self._height)
        cast = cast_rays(
            origins, directions, self.segments, cfg.max_range_m, cylinders=cylinders,
            max_bounces=cfg.max_bounces, glass_returns=glass,
            level_group=rings if self._level else 0,
        )  # fmt: skip
        measured = cast.range_m + noise
        keep = (
            np.isfinite(cast.range_m)
            & (measured >= cfg.min_range_m)
            & (measured <= cfg.max_range_m)
        )
        beams = np.flatnonzero(keep)
        points = measured[beams, None] * self.directions_lidar.reshape(-1, 3)[beams]
        intensity = np.array([_INTENSITY.get(int(k), 0.0) for k in range(5)])[cast.kind[beams]]
        intensity = np.where(cast.bounces[beams] > 0, _MIRRORED_INTENSITY, intensity)
        offsets = np.repeat(self.column_offsets_s, rings)[beams]
        msg = PointCloudMsg(
            int(start_ns), LIDAR_FRAME, points.astype(np.float32), intensity.astype(np.float32),
            offsets.astype(np.float32),
        )  # fmt: skip
        end = int(start_ns) + round(float(np.float32(self.column_offsets_s[-1])) * S_NS)
        return Sweep(msg, cast, beams, R, origins_c, end)

    def sweeps(
        self, xy_yaw_at: PoseFunction, starts_ns: npt.NDArray[np.int64], first_index: int = 0
    ) -> Iterator[Sweep]:
        """:meth:`sweep` for each of ``starts_ns`` (indices from ``first_index``), lazily; the
        true poses are sampled for 100 sweeps at a time."""
        starts = np.asarray(starts_ns, dtype=np.int64)
        for lo in range(0, len(starts), 100):
            chunk = starts[lo : lo + 100]
            knots = np.concatenate([self._knots(int(s)) for s in chunk])
            table = np.asarray(xy_yaw_at(knots), dtype=np.float64)
            for i, start in enumerate(chunk.tolist()):
                yield self.sweep(
                    _Table(table[i * _KNOTS : (i + 1) * _KNOTS]), start, first_index + lo + i
                )

    def _knots(self, start_ns: int) -> npt.NDArray[np.int64]:
        last = start_ns + round(float(self.column_offsets_s[-1]) * S_NS)
        return np.linspace(start_ns, last, _KNOTS).round().astype(np.int64)

    def _column_poses(
        self, xy_yaw_at: PoseFunction, stamps: npt.NDArray[np.int64]
    ) -> tuple[FloatArray, FloatArray]:
        """``R_map_lidar`` (C, 3, 3) and ``t_map_lidar`` (C, 3) at the column stamps. The base
        pose is sampled at 11 instants over the sweep and interpolated linearly in x, y and
        (unwrapped) yaw: a 0.8 m/s arc of 0.5 m radius strays < 0.1 mm from it."""
        knots = self._knots(int(stamps[0]))
        xy_yaw = np.asarray(xy_yaw_at(knots), dtype=np.float64)
        if len(stamps) == 1:
            xy_yaw, knots = xy_yaw[:1], knots[:1]
        tk, tc = (knots - knots[0]).astype(np.float64), (stamps - knots[0]).astype(np.float64)
        yaw_k = np.unwrap(xy_yaw[:, 2])
        x, y, yaw = (np.interp(tc, tk, v) for v in (xy_yaw[:, 0], xy_yaw[:, 1], yaw_k))
        c, s = np.cos(yaw), np.sin(yaw)
        R_map_base = np.zeros((len(yaw), 3, 3))
        R_map_base[:, 0, 0], R_map_base[:, 0, 1], R_map_base[:, 1, 0] = c, -s, s
        R_map_base[:, 1, 1], R_map_base[:, 2, 2] = c, 1.0
        R_bl = self.T_base_lidar.rotation.matrix
        t_bl = np.asarray(self.T_base_lidar.translation)
        origins = R_map_base @ t_bl + np.column_stack([x, y, np.zeros_like(x)])
        return R_map_base @ R_bl, origins

    def scan_at(self, T_map_base: SE3) -> tuple[FloatArray, CastResult]:
        """Every beam of one sweep from a *standing* base pose (no motion, no noise, no
        people): ``(points_map (M, 3) of the returns, cast)``. For premaps and tests."""
        T_map_lidar = T_map_base @ self.T_base_lidar
        d_lidar = self.directions_lidar.reshape(-1, 3)
        directions = d_lidar @ T_map_lidar.rotation.matrix.T
        origins = np.broadcast_to(np.asarray(T_map_lidar.translation), directions.shape)
        cfg = self.config
        level = abs(T_map_lidar.rotation.matrix[2, 2] - 1.0) < 1e-12
        rings = self.directions_lidar.shape[1]
        cast = cast_rays(
            origins, directions, self.segments, cfg.max_range_m, max_bounces=cfg.max_bounces,
            level_group=rings if level else 0,
        )  # fmt: skip
        ok = np.isfinite(cast.range_m) & (cast.range_m >= cfg.min_range_m)
        return np.asarray(T_map_lidar.act(cast.range_m[ok, None] * d_lidar[ok])), cast


@dataclass(frozen=True, slots=True)
class _Table:
    """A :data:`PoseFunction` returning poses already sampled at a sweep's knots."""

    rows: FloatArray

    def __call__(self, stamps_ns: npt.NDArray[np.int64]) -> FloatArray:
        return self.rows


def premap_from_world(
    world: World,
    T_map_base: SE3,
    *,
    config: LidarConfig | None = None,
    every_m: float = 0.5,
    voxel_m: float = 0.1,
) -> FloatArray:
    """A truth premap: scans of the world's lidar at the *true* poses ``T_map_base`` (a batch,
    e.g. a drive's ground truth), taken every ``every_m`` of travel (and at the first pose),
    without motion, noise or people, merged in ``map`` and voxel-downsampled (one centroid per
    ``voxel_m`` cube). Mirrors add their phantom geometry, as a premap made with a real scanner
    has it.

    Parameters
    ----------
    world : World
    T_map_base : SE3 batch
    config : LidarConfig, optional
        Default ``world.robot.lidar``.

    Returns
    -------
    (N, 3) float64
        Points in ``map``, metres.

    Raises
    ------
    ValueError
        If neither ``config`` nor the world's robot has a lidar.
    """
    config = config or world.robot.lidar
    if config is None:
        raise ValueError("premap_from_world: the world's robot has no lidar; pass config=")
    sim = LidarSimulator(config, world.walls_in_map())
    xy = np.asarray(T_map_base.translation).reshape(-1, 3)[:, :2]
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xy, axis=0), axis=1))])
    marks = np.floor(travelled / every_m)
    picks = np.flatnonzero(np.diff(marks, prepend=-1.0) > 0)
    voxels = VoxelCentroids(voxel_m, centred=True)  # scan by scan: memory grows with the
    for i in picks:  # ground covered, not with the drive
        voxels.add(sim.scan_at(T_map_base[int(i)])[0])
    return voxels.centroids()
