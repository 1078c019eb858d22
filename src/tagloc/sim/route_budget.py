"""Limits that keep a valid world's drive finite and affordable.

A world that passes validation must also be drivable: ``world coverage``, ``sim record``, ``map
build --sim`` and ``demo`` sample its route at the odometry and camera rates and keep every
sample in memory. :func:`check_route_budget` plans the route (cheap: one piece per waypoint) and
refuses it when it is degenerate (fewer than two distinct waypoints) or would need more than
:data:`MAX_ODOM_SAMPLES` odometry samples or :data:`MAX_CAMERA_FRAMES` camera frames (a tiny
speed or acceleration, an hour-long dwell at 2 kHz). The built-in office route, driven twice,
takes 70 000 odometry samples and 21 000 camera frames.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping

from tagloc.config import FieldPathError
from tagloc.sim.route import RouteConfig
from tagloc.sim.trajectory import RoutePlan, plan_from_config

#: Most route pieces planned (waypoints times ``repeat``).
MAX_ROUTE_WAYPOINTS = 20_000
#: Most odometry samples of one drive (about 83 min at 100 Hz; a few hundred MB of ground truth).
MAX_ODOM_SAMPLES = 500_000
#: Most camera frames of one drive (about 83 min at 30 Hz).
MAX_CAMERA_FRAMES = 150_000


def check_route_budget(
    route: RouteConfig,
    checkpoints_xy: Mapping[str, tuple[float, float]],
    odom_rate_hz: float,
    camera_rate_hz: float,
    plan: Callable[[], RoutePlan] | None = None,
) -> RoutePlan:
    """Plan ``route`` and check that driving it stays within the limits above.

    Parameters
    ----------
    route : RouteConfig
        Its ``repeat`` counts (pass a copy with the number of laps to be driven).
    checkpoints_xy : mapping of str to (x, y)
        Every checkpoint the route names, map frame, metres.
    odom_rate_hz, camera_rate_hz : float
        Sampling rates of the drive.
    plan : callable, optional
        Plans the route instead of :func:`~tagloc.sim.trajectory.plan_from_config` (a route
        that rides elevators).

    Returns
    -------
    RoutePlan
        The plan (so a caller need not plan twice).

    Raises
    ------
    FieldPathError
        At ``route.waypoints`` for fewer than two distinct waypoints or too many of them, at
        ``route`` for a drive that would need too many samples; the message gives the numbers.
    """
    if len(route.waypoints) * route.repeat > MAX_ROUTE_WAYPOINTS:
        raise FieldPathError(
            ("route", "waypoints"),
            f"{len(route.waypoints)} waypoints x repeat {route.repeat} is more than "
            f"{MAX_ROUTE_WAYPOINTS}",
        )
    try:
        planned = plan() if plan is not None else plan_from_config(route, checkpoints_xy)
    except FieldPathError:
        raise
    except ValueError:
        raise FieldPathError(
            ("route", "waypoints"),
            "the route needs at least two distinct waypoints (consecutive repeats are merged)",
        ) from None
    duration_s = planned.total_duration_s
    for samples, limit, what in (
        (duration_s * odom_rate_hz, MAX_ODOM_SAMPLES, "odometry samples at robot.odom_rate_hz"),
        (duration_s * camera_rate_hz, MAX_CAMERA_FRAMES, "camera frames at robot.camera.rate_hz"),
    ):
        if not samples <= limit:  # also NaN
            raise FieldPathError(
                ("route",),
                f"driving the route ({planned.length_m:.0f} m, repeat {route.repeat}) takes "
                f"{duration_s:.0f} s, {_count(samples)} {what}, more than {limit}; raise the "
                "speed or accelerations, shorten the dwells or the route",
            )
    return planned


def _count(samples: float) -> str:
    return f"{samples:.3g}" if not math.isfinite(samples) or samples >= 1e6 else f"{samples:.0f}"
