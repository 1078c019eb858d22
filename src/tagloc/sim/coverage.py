"""Tag coverage of a world's route: where the robot drives with no tag in view.

Commissioning question: *where along the route does the camera see no tag, and for how far?*
Between two sightings the robot runs on odometry alone, and a survey ties the tags on either side
together only through that odometry; on a legged robot a blind stretch of 1 m and 45 deg of turn
already costs about 1 deg of yaw (see the README, "The tag map"). This module drives the route
once (ground truth; the odometry model plays no part), asks at every ``stride``-th camera frame
which tags are in view by the simulated detector's rules
(:func:`tagloc.sim.simulate_observations`: facing the camera, in range, inside the image, not
behind an opaque wall), and reports every *gap*: a maximal run of frames with no tag in view.

A gap is measured on the true path from the last frame with a tag to the first frame with one
again: distance travelled (m), rotation (sum of absolute yaw change, deg), where it starts and
ends, and which tags were in view on either side. Gaps shorter than both ``min_distance_m`` and
``min_rotation_deg`` are left out (a tag slipping out of view for a frame or two).

Example
-------
>>> from tagloc.sim import load_default_world
>>> from tagloc.sim.coverage import route_coverage
>>> report = route_coverage(load_default_world())                      # doctest: +SKIP
>>> report.covered_fraction, report.gaps[0].distance_m                 # doctest: +SKIP
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from tagloc._types import FloatArray
from tagloc.config import FieldPathError
from tagloc.errors import SimulationError
from tagloc.sim.drive import simulate_drive
from tagloc.sim.observations import ObservationConfig, simulate_observations
from tagloc.sim.route_budget import check_route_budget
from tagloc.sim.world import World

__all__ = ["CoverageGap", "RouteCoverage", "gaps_csv", "route_coverage"]

S = 1_000_000_000


@dataclass(frozen=True, slots=True)
class CoverageGap:
    """One stretch of the route with no tag in view (module docstring).

    Attributes
    ----------
    start_s, end_s : float
        Time since the start of the route of the last frame with a tag before the gap and of the
        first frame with one after it, s.
    start_xy, end_xy : tuple of float
        Base position (map, m) at those frames.
    distance_m, rotation_deg : float
        True distance travelled and absolute yaw turned between them.
    tags_before, tags_after : tuple of int
        Tag ids in view at those frames (empty at the start or end of the route).
    """

    start_s: float
    end_s: float
    start_xy: tuple[float, float]
    end_xy: tuple[float, float]
    distance_m: float
    rotation_deg: float
    tags_before: tuple[int, ...]
    tags_after: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class RouteCoverage:
    """Coverage of one drive of the route.

    Attributes
    ----------
    length_m : float
        Route length driven, m.
    frames : int
        Camera frames checked.
    covered_fraction : float
        Fraction of the distance travelled between consecutive checked frames of which at least
        one frame had a tag in view.
    gaps : tuple of CoverageGap
        In route order.
    """

    length_m: float
    frames: int
    covered_fraction: float
    gaps: tuple[CoverageGap, ...]

    def longest(self) -> CoverageGap | None:
        """The gap with the longest distance (None if there is none)."""
        return max(self.gaps, key=lambda g: g.distance_m, default=None)


def route_coverage(
    world: World,
    config: ObservationConfig | None = None,
    *,
    laps: int = 1,
    stride: int = 3,
    min_distance_m: float = 1.0,
    min_rotation_deg: float = 30.0,
) -> RouteCoverage:
    """Drive ``laps`` laps of ``world``'s route and list where no tag is in view.

    Parameters
    ----------
    world : World
    config : ObservationConfig, optional
        The detector's visibility rules (range, viewing angle, image margin, minimum size);
        noise, detection probability and glints play no part.
    laps : int
        Laps of the route (``world.route.repeat`` is replaced).
    stride : int
        Check every ``stride``-th camera frame.
    min_distance_m, min_rotation_deg : float
        A gap is kept if it reaches either.

    Raises
    ------
    SimulationError
        ``laps`` or ``stride`` below 1, or so many laps that the drive exceeds the limits of
        :mod:`tagloc.sim.route_budget`.
    """
    if laps < 1 or stride < 1:
        raise SimulationError(f"coverage needs laps >= 1 and stride >= 1, got {laps}, {stride}")
    route = world.route.model_copy(update={"repeat": laps})
    try:
        check_route_budget(
            route, world.checkpoints_xy(), world.robot.odom_rate_hz, world.robot.camera.rate_hz
        )
    except FieldPathError as exc:
        raise SimulationError(f"{laps} laps: {exc}") from None
    world = world.model_copy(update={"route": route})
    drive = simulate_drive(world, seed=0)
    stamps = drive.camera_stamps_ns[::stride]
    seen = [
        tuple(sorted({s.tag_id for s in frame.truth}))
        for frame in simulate_observations(drive, config or ObservationConfig(), stamps_ns=stamps)
    ]
    truth = drive.ground_truth_at(stamps)
    xy, yaw = truth.xy_yaw_map_base[:, :2], truth.xy_yaw_map_base[:, 2]  # yaw is continuous
    step_m = np.diff(truth.distance_m)  # along the path, not the chord
    step_rad = np.abs(np.diff(yaw))
    in_view = np.array([bool(ids) for ids in seen])
    covered = in_view[:-1] | in_view[1:]
    total = float(step_m.sum())
    gaps = [
        gap
        for gap in _gaps(in_view, seen, stamps - drive.t0_ns, xy, step_m, step_rad)
        if gap.distance_m >= min_distance_m or gap.rotation_deg >= min_rotation_deg
    ]
    return RouteCoverage(
        length_m=total,
        frames=len(stamps),
        covered_fraction=float(step_m[covered].sum() / total) if total > 0 else 1.0,
        gaps=tuple(gaps),
    )


def _gaps(
    in_view: npt.NDArray[np.bool_],
    seen: list[tuple[int, ...]],
    t_ns: npt.NDArray[np.int64],
    xy: FloatArray,
    step_m: FloatArray,
    step_rad: FloatArray,
) -> list[CoverageGap]:
    """Every maximal run of frames without a tag, from the frame before it to the one after."""
    blind = np.flatnonzero(~in_view)
    if len(blind) == 0:
        return []
    breaks = np.flatnonzero(np.diff(blind) > 1)
    starts = np.concatenate([[blind[0]], blind[breaks + 1]])
    ends = np.concatenate([blind[breaks], [blind[-1]]])
    last = len(in_view) - 1
    out = []
    for first_blind, last_blind in zip(starts.tolist(), ends.tolist(), strict=True):
        a, b = max(first_blind - 1, 0), min(last_blind + 1, last)
        out.append(
            CoverageGap(
                start_s=float(t_ns[a] / S),
                end_s=float(t_ns[b] / S),
                start_xy=(float(xy[a, 0]), float(xy[a, 1])),
                end_xy=(float(xy[b, 0]), float(xy[b, 1])),
                distance_m=float(step_m[a:b].sum()),
                rotation_deg=math.degrees(float(step_rad[a:b].sum())),
                tags_before=seen[a],
                tags_after=seen[b],
            )
        )
    return out


def gaps_csv(report: RouteCoverage) -> str:
    """The gaps as CSV text: one row per gap, seconds, metres and degrees; tag ids separated by
    spaces."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["start_s", "end_s", "start_x", "start_y", "end_x", "end_y",
                     "distance_m", "rotation_deg", "tags_before", "tags_after"])  # fmt: skip
    for g in report.gaps:
        metres = (*g.start_xy, *g.end_xy, g.distance_m)
        writer.writerow([
            f"{g.start_s:.3f}", f"{g.end_s:.3f}", *(f"{v:.3f}" for v in metres),
            f"{g.rotation_deg:.1f}", " ".join(map(str, g.tags_before)),
            " ".join(map(str, g.tags_after)),
        ])  # fmt: skip
    return buffer.getvalue()
