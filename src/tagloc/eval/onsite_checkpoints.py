"""Checkpoint repeatability: how much the fused pose scatters each time the robot stops at the
same floor point.

A stop is a stretch of at least ``min_stop_s`` seconds in which the odometry moves less than
``still_speed_mps`` (turning in place counts). Each stop's fused ``T_map_base`` (mean position,
circular-mean yaw over the stop) is assigned to the nearest named checkpoint within its
``radius``; without a checkpoint file, stops within ``cluster_radius_m`` of each other are one
unnamed checkpoint (``stop_1``, ...). The spread of a checkpoint's visits (RMS distance from
their mean, largest distance, yaw standard deviation) is the repeatability of localization at
that place: a docking robot needs it small, whatever the absolute error.

The checkpoint file (:class:`CheckpointsFile`): ``checkpoints: [{name, x, y, radius}]``, x and
y in the map frame, metres (the ``checkpoints`` of a world file parse as such, radius 0.5 m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from pydantic import Field, model_validator

from tagloc.config import FieldPathError, StrictModel, parse_yaml_mapping, short_repr, validate
from tagloc.localize.run import LocalizationRun
from tagloc.units import S_NS

__all__ = [
    "CheckpointSpec",
    "CheckpointSpread",
    "CheckpointsFile",
    "Stop",
    "checkpoint_spreads",
    "detect_stops",
    "parse_checkpoints",
]



class CheckpointSpec(StrictModel):
    """A named floor point in ``map`` (m) and the radius within which a stop is a visit."""

    name: str = Field(min_length=1, max_length=200)
    x: float = Field(allow_inf_nan=False)
    y: float = Field(allow_inf_nan=False)
    radius: float = Field(default=0.5, gt=0.0, le=100.0)
    note: str | None = None


class CheckpointsFile(StrictModel):
    """``checkpoints.yaml``: a list of :class:`CheckpointSpec` (other top-level keys, such as a
    world file's, are ignored by :func:`parse_checkpoints`)."""

    checkpoints: tuple[CheckpointSpec, ...] = Field(min_length=1)

    @model_validator(mode="after")
    def _unique_names(self) -> CheckpointsFile:
        first: dict[str, int] = {}
        for k, spec in enumerate(self.checkpoints):
            if spec.name in first:  # their visits would be merged into one spread
                where = f"first at checkpoints[{first[spec.name]}]"
                raise FieldPathError(
                    ("checkpoints", k, "name"), f"duplicate name {short_repr(spec.name)} ({where})"
                )
            first[spec.name] = k
        return self


def parse_checkpoints(text: str, source: str) -> tuple[CheckpointSpec, ...]:
    """The ``checkpoints`` list of a YAML text (a checkpoints file or a world file).

    Raises
    ------
    ConfigError
        One line naming ``source`` and the field.
    """
    data = parse_yaml_mapping(text, source)
    return validate(CheckpointsFile, {"checkpoints": data.get("checkpoints")}, source).checkpoints


@dataclass(frozen=True, slots=True)
class Stop:
    """The robot standing still: ``[start_ns, end_ns]`` and its fused pose (x, y m, yaw rad)."""

    start_ns: int
    end_ns: int
    x: float
    y: float
    yaw: float


@dataclass(frozen=True, slots=True)
class CheckpointSpread:
    """The visits of one checkpoint and their spread (m, deg)."""

    name: str
    visits: tuple[Stop, ...]
    rms_m: float
    max_m: float
    yaw_std_deg: float

    def to_dict(self) -> dict[str, Any]:
        x, y = np.mean([s.x for s in self.visits]), np.mean([s.y for s in self.visits])
        return {
            "name": self.name, "visits": len(self.visits), "mean_xy_m": [float(x), float(y)],
            "rms_m": self.rms_m, "max_m": self.max_m, "yaw_std_deg": self.yaw_std_deg,
        }  # fmt: skip


def detect_stops(
    run: LocalizationRun, *, min_stop_s: float = 2.0, still_speed_mps: float = 0.02
) -> list[Stop]:
    """Stretches where the odometry's speed stays below ``still_speed_mps`` for at least
    ``min_stop_s`` seconds, with the fused pose averaged over them (initialized rows only)."""
    stamps = run.stamps_ns
    if len(stamps) < 2:
        return []
    p = run.T_odom_base.translation
    dt = np.diff(stamps) / S_NS
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.maximum(dt, 1e-9)
    still = np.concatenate([[False], speed < still_speed_mps, [False]])
    edges = np.flatnonzero(np.diff(still.astype(np.int8)))
    T_map_base = run.T_map_base
    stops = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # rows a..b are still
        if (stamps[b] - stamps[a]) / S_NS < min_stop_s:
            continue
        rows = np.arange(a, b + 1)[run.initialized[a : b + 1]]
        if rows.size == 0:
            continue
        xy = T_map_base.translation[rows, :2].mean(axis=0)
        heading = T_map_base.rotation.matrix[rows, :, 0]
        yaw = math.atan2(float(heading[:, 1].mean()), float(heading[:, 0].mean()))
        stops.append(Stop(int(stamps[a]), int(stamps[b]), float(xy[0]), float(xy[1]), yaw))
    return stops


def checkpoint_spreads(
    stops: list[Stop],
    checkpoints: tuple[CheckpointSpec, ...] | None = None,
    *,
    cluster_radius_m: float = 0.5,
) -> list[CheckpointSpread]:
    """Group ``stops`` by checkpoint (module docstring) and measure each group's spread.
    Checkpoints with fewer than two visits are left out (no spread to measure)."""
    groups: dict[str, list[Stop]] = {}
    if checkpoints is not None:
        centres = np.array([[c.x, c.y] for c in checkpoints])
        for s in stops:
            d = np.hypot(centres[:, 0] - s.x, centres[:, 1] - s.y)
            k = int(np.argmin(d))
            if d[k] <= checkpoints[k].radius:
                groups.setdefault(checkpoints[k].name, []).append(s)
    else:
        means: list[npt.NDArray[np.float64]] = []
        for s in stops:
            dist = [float(np.hypot(m[0] - s.x, m[1] - s.y)) for m in means]
            k = int(np.argmin(dist)) if dist else -1
            if k < 0 or dist[k] > cluster_radius_m:
                means.append(np.array([s.x, s.y]))
                k = len(means) - 1
            name = f"stop_{k + 1}"
            groups.setdefault(name, []).append(s)
            members = groups[name]
            means[k] = np.array([np.mean([m.x for m in members]), np.mean([m.y for m in members])])
    out = []
    for name, visits in groups.items():
        if len(visits) < 2:
            continue
        xy = np.array([[v.x, v.y] for v in visits])
        r = np.linalg.norm(xy - xy.mean(axis=0), axis=1)
        yaws = np.array([v.yaw for v in visits])
        resultant = float(np.hypot(np.cos(yaws).mean(), np.sin(yaws).mean()))
        yaw_std = math.degrees(math.sqrt(max(-2.0 * math.log(max(resultant, 1e-12)), 0.0)))
        out.append(
            CheckpointSpread(
                name, tuple(visits), float(np.sqrt(np.mean(r**2))), float(r.max()), yaw_std
            )
        )
    return sorted(out, key=lambda c: c.name)
