"""The lidar part of a survey: sweeps with their stamps and the scanner's mount.

Plain data, like :class:`~tagloc.mapping.survey.Survey` that holds it. Each sweep keeps its
points as measured, in the scanner frame ``lidar`` at the time of each point, with per-point time
offsets after the sweep's stamp (``None``: all points at the stamp, or already de-skewed to it);
the builder de-skews the sweeps it uses with the survey's odometry
(:mod:`tagloc.mapping.lidar_survey`). A survey source need not keep every sweep of a 10 Hz
scanner: the builder uses one every :attr:`~tagloc.mapping.lidar_config.LidarSurveyConfig.
keyframe_distance_m` of travel, so the sources keep a sweep every few tens of centimetres
(:func:`select_sweeps`) and the survey's memory stays small.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.errors import TaglocError
from tagloc.geometry import SE3


class SurveyScanError(TaglocError, ValueError):
    """Lidar data of a survey that cannot be used; the message names the field at fault."""


@dataclass(frozen=True, slots=True, eq=False)
class SurveyScans:
    """Lidar sweeps of a survey drive.

    Attributes
    ----------
    stamps_ns : (S,) int64
        Sweep start stamps, strictly increasing.
    points_lidar : tuple of S (N_i, 3) float arrays
        Points in the scanner frame, metres; non-finite rows (no return) are allowed and dropped.
    time_offset_s : tuple of S (N_i,) float arrays or None
        Seconds after the stamp at which each point was measured (None: at the stamp).
    T_base_lidar : SE3
        The scanner's mount in ``base``.
    """

    stamps_ns: npt.NDArray[np.int64]
    points_lidar: tuple[npt.NDArray[np.floating], ...]
    time_offset_s: tuple[npt.NDArray[np.floating] | None, ...]
    T_base_lidar: SE3

    def __post_init__(self) -> None:
        stamps = np.asarray(self.stamps_ns, dtype=np.int64).reshape(-1)
        if len(stamps) != len(self.points_lidar) or len(stamps) != len(self.time_offset_s):
            raise SurveyScanError(
                f"lidar: {len(stamps)} stamps, {len(self.points_lidar)} point sets and "
                f"{len(self.time_offset_s)} time offset sets: must match"
            )
        if len(stamps) > 1 and not (np.diff(stamps) > 0).all():
            raise SurveyScanError("lidar: sweep stamps must increase strictly")
        for i, (points, offsets) in enumerate(zip(self.points_lidar, self.time_offset_s,
                                                  strict=True)):  # fmt: skip
            if points.ndim != 2 or points.shape[1] != 3:
                raise SurveyScanError(
                    f"lidar: sweep {i}: points must be (N, 3), got {points.shape}"
                )
            if offsets is not None and offsets.shape != (len(points),):
                raise SurveyScanError(
                    f"lidar: sweep {i}: {len(points)} points but {offsets.shape} time offsets"
                )
        if self.T_base_lidar.is_batch:
            raise SurveyScanError("lidar: T_base_lidar must be a single pose")
        object.__setattr__(self, "stamps_ns", stamps)

    def __len__(self) -> int:
        return len(self.stamps_ns)


def select_sweeps(
    positions_m: FloatArray, yaw_rad: FloatArray, min_distance_m: float, min_turn_rad: float
) -> npt.NDArray[np.int64]:
    """Indices of the sweeps to keep: the first, then each one at least ``min_distance_m`` or
    ``min_turn_rad`` (of yaw) from the last kept one (``positions_m (S, 3)``, ``yaw_rad (S,)``
    from odometry at the sweep stamps)."""
    keep = [0] if len(positions_m) else []
    for i in range(1, len(positions_m)):
        j = keep[-1]
        turn = abs(np.angle(np.exp(1j * (yaw_rad[i] - yaw_rad[j]))))
        moved = float(np.linalg.norm(positions_m[i] - positions_m[j]))
        if moved >= min_distance_m or turn >= min_turn_rad:
            keep.append(i)
    return np.asarray(keep, dtype=np.int64)
