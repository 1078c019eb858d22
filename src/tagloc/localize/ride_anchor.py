"""The pose in ``map`` through an elevator ride: carried by the cab, then settled on the landing.

A shaft is vertical, so a cab stands at the same x, y and yaw at every floor, and its floor is
at the floor's height: in the floor's frame (:mod:`tagloc.localize.floors`) the cab's pose
``T_floor_cab`` is the same at every landing. While the robot rides, the map's tags are out of
sight, but the cab's tags measure the robot relative to the cab (the cab's estimate,
``T_cab_odom``). So:

1. **boarding** (from the cab's first tags to the doors closing): at each odometry sample the
   cab's pose in the floor's frame is measured from both estimates,
   ``T_floor_cab = T_floor_base @ inv(T_cab_base)``, with its covariance; the most certain
   measurement of the boarding (in x, y: typically just after a map tag's fix, before the walk
   into the cab drifts) is fused with the earlier rides' when the doors close (the same shaft:
   an information-weighted mean in the tangent space, :class:`CabPlacement`);
2. **alighting** (the doors open at a landing): the ``map -> odom`` filter is set to the pose
   carried from the cab, ``T_floor_odom = T_floor_cab @ T_cab_odom``, with the covariance of
   both (:meth:`RideAnchor.alighted`); the floor (and so z) stays the landing's tags' to give;
3. **settling** (until the robot walked ``landing_settle_m`` or a landing tag is seen from within
   ``landing_near_m``): the landing's tags seen from the doors are metres away, head-on, and a
   single tag's orientation is poorly measured there; the fix's error is then a rotation of the
   whole view about the tag's vertical axis, which moves the base by the range times the angle,
   the same for every fix of that view, and its range is as poorly known. Each such fix gets the
   covariance of that rotation and of a range error of the range times the same angle
   (``landing_tilt_sigma_rad``, :func:`tilt_covariance`, :func:`range_covariance`) added, and
   the ``n``-th fix of a tag from
   one viewpoint (within ``landing_viewpoint_m`` of travel) counts ``1/n`` of a fix (its
   covariance times ``n``): fixes sharing one error do not add up to certainty
   (:class:`LandingSettle`). They still confirm the floor; they no longer drag the carried pose
   to their bias.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping

import numpy as np

from tagloc._types import FloatArray
from tagloc.errors import TaglocError
from tagloc.geometry import SE3, cov_compose, cov_inverse
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import TagFix
from tagloc.localize.floors import FloorFilter, FloorFrame, tag_ids_of
from tagloc.supervise import CabState, CabTransition, ElevatorConfig

__all__ = ["CabPlacement", "LandingSettle", "RideAnchor", "range_covariance", "tilt_covariance"]

logger = logging.getLogger(__name__)

#: Added to every diagonal (m^2, rad^2) so a planar filter's unmeasured directions stay invertible.
_EPS = 1e-10


def _regular(cov: FloatArray) -> FloatArray:
    out = 0.5 * (np.asarray(cov, dtype=np.float64) + np.asarray(cov, dtype=np.float64).T)
    return out + _EPS * np.eye(out.shape[0])


class CabPlacement:
    """The cab's pose in the floor's frame, ``T_floor_cab`` with its ``(6, 6)`` covariance,
    fused over the rides' measurements (a Kalman update of a constant in the tangent space)."""

    def __init__(self) -> None:
        self.T_floor_cab: SE3 | None = None
        self.cov: FloatArray | None = None
        self.measurements = 0

    def add(self, T_floor_cab: SE3, cov: FloatArray) -> None:
        """One more measurement of the cab's pose (right-tangent covariance ``cov``)."""
        cov = _regular(cov)
        self.measurements += 1
        if self.T_floor_cab is None or self.cov is None:
            self.T_floor_cab, self.cov = T_floor_cab, cov
            return
        delta = T_floor_cab.minus(self.T_floor_cab)  # the measurement in the current's tangent
        gain = self.cov @ np.linalg.inv(self.cov + cov)
        self.T_floor_cab = self.T_floor_cab.plus(gain @ delta)
        self.cov = _regular((np.eye(6) - gain) @ self.cov)


def tilt_covariance(T_map_base: SE3, p_map_tag: FloatArray, sigma_rad: float) -> FloatArray:
    """``(6, 6)`` right-tangent covariance of a fix whose view is rotated by ``N(0, sigma_rad^2)``
    about the vertical axis through the tag at ``p_map_tag`` ((3,), m).

    Rotating the base by ``e`` about that axis moves it by ``e * z x (p_base - p_tag)``; in the
    base's tangent that is ``e * J`` with ``J = [v_y, -v_x, 0, 0, 0, 1]``, ``v`` the tag in the
    base frame (an upright base: its z is the map's). Rank one: ``sigma^2 J J^T``.
    """
    v_base = T_map_base.inverse().act(np.asarray(p_map_tag, dtype=np.float64))
    J = np.array([v_base[1], -v_base[0], 0.0, 0.0, 0.0, 1.0])
    return float(sigma_rad) ** 2 * np.outer(J, J)


def range_covariance(T_map_base: SE3, p_map_tag: FloatArray, sigma_rad: float) -> FloatArray:
    """``(6, 6)`` right-tangent covariance of a fix whose range to the tag at ``p_map_tag`` is
    off by ``N(0, (r * sigma_rad)^2)`` along the horizontal line of sight (``r`` its horizontal
    range): the far tag's scale is as poorly measured as its turn."""
    v_base = T_map_base.inverse().act(np.asarray(p_map_tag, dtype=np.float64))
    out = np.zeros((6, 6))
    out[:2, :2] = float(sigma_rad) ** 2 * np.outer(v_base[:2], v_base[:2])
    return out


class LandingSettle:
    """Far landing tags' fixes after an exit, weighted for the error a view shares (module
    docstring, step 3). ``weigh`` each map fix; :attr:`done` once settled."""

    def __init__(
        self, config: ElevatorConfig, odometer_m: float,
        tag_positions_map: Mapping[int, FloatArray],
    ) -> None:  # fmt: skip
        self._c, self._start_m = config, odometer_m
        self._tags = tag_positions_map
        self._views: dict[int, tuple[float, int]] = {}  # tag -> (odometer at the view, fixes)
        self.done = False
        self.weighed = 0

    def weigh(self, fix: TagFix, odometer_m: float) -> TagFix:
        """``fix`` as the filter should take it (the same object when nothing changes)."""
        c = self._c
        if odometer_m - self._start_m >= c.landing_settle_m:
            self.done = True
            return fix
        ids = [i for i in tag_ids_of(fix.source) if i in self._tags]
        if not ids:
            return fix
        if not fix.quality.range_m > c.landing_near_m:  # a near tag in view: settled
            self.done = True
            return fix
        tag_id = ids[0]
        since_m, n = self._views.get(tag_id, (odometer_m, 0))
        if odometer_m - since_m >= c.landing_viewpoint_m:
            since_m, n = odometer_m, 0
        self._views[tag_id] = (since_m, n + 1)
        p_tag, sigma = self._tags[tag_id], c.landing_tilt_sigma_rad
        view = tilt_covariance(fix.T_map_base, p_tag, sigma)
        view += range_covariance(fix.T_map_base, p_tag, sigma)
        self.weighed += 1
        return dataclasses.replace(fix, cov=(n + 1) * (np.asarray(fix.cov) + view))


class RideAnchor:
    """The node's ride anchor (module docstring): :meth:`moved` at each move of the handoff
    (:meth:`boarded` when the doors close on a ride, :meth:`alighted` when they open at a
    landing); nothing unless ``elevators.carry_through_ride``."""

    def __init__(self, config: ElevatorConfig, tag_positions_map: Mapping[int, FloatArray]) -> None:
        self._c = config
        self._tags = dict(tag_positions_map)
        self.placement = CabPlacement()
        self.anchored = 0
        self._best: tuple[float, SE3, FloatArray] | None = None  # the boarding's: xy var, pose, cov

    def moved(
        self, move: CabTransition, main: MapOdomFilter, cab: MapOdomFilter, floors: FloorFrame,
        floor_known: bool,
    ) -> None:  # fmt: skip
        """A move of the handoff, with the node's ``map -> odom`` filter and the cab's."""
        if not self._c.carry_through_ride:
            return
        came, went = move.from_state, move.to_state
        # a door message may be ahead of the odometry: at the newest sample the filter knows
        stamp_ns = min(move.stamp_ns, main.stamp_ns) if main.initialized else move.stamp_ns
        if came is CabState.BOARDING and went is CabState.IN_CAB and floor_known:
            self.observe(stamp_ns, main, cab, floors)
            if self._best is not None:
                self.placement.add(self._best[1], self._best[2])
                logger.info(
                    "%d cab placed at %s in the floor's frame (%d rides)", stamp_ns,
                    np.round(self.placement.T_floor_cab.translation, 3),  # type: ignore[union-attr]
                    self.placement.measurements,
                )  # fmt: skip
        if came is CabState.BOARDING:
            self._best = None
        if came is CabState.IN_CAB and went is CabState.ALIGHTING:
            settle = self.alighted(stamp_ns, main, cab, floors)
            if settle is not None and isinstance(main, FloorFilter):
                main.weigher = settle

    def observe(
        self, stamp_ns: int, main: MapOdomFilter, cab: MapOdomFilter, floors: FloorFrame
    ) -> None:
        """Boarding (the floor known): measure the cab's pose in the floor's frame from both
        estimates at ``stamp_ns``; the boarding's most certain measurement is kept."""
        if not self._c.carry_through_ride:
            return
        if not (main.initialized and cab.initialized) or main.reacquiring:
            return
        try:
            T_map_base, T_cab_base = main.pose_at(stamp_ns), cab.pose_at(stamp_ns)
        except TaglocError:  # no odometry there (yet)
            return
        T_floor_base = floors.lift(T_map_base.T_map_base, -floors.height_m)
        T_base_cab = T_cab_base.T_map_base.inverse()
        cov_base_cab = cov_inverse(T_cab_base.T_map_base, _regular(T_cab_base.cov))
        T_floor_cab = T_floor_base @ T_base_cab
        cov = cov_compose(T_floor_base, _regular(T_map_base.cov), T_base_cab, cov_base_cab)
        var_xy = float(np.trace(cov[:2, :2]))
        if self._best is None or var_xy < self._best[0]:
            self._best = (var_xy, T_floor_cab, cov)

    def cab_start(self, main: MapOdomFilter, floors: FloorFrame) -> tuple[SE3, FloatArray] | None:
        """The cab's estimate before any cab fix: the map estimate carried into the cab by the
        cab's placement, ``T_cab_odom = inv(T_floor_cab) @ T_floor_odom``, with the covariance
        of both; None before a ride placed the cab, or while the map estimate is not there or
        re-acquiring (the floor must be known: the caller's to check)."""
        placed, P = self.placement.T_floor_cab, self.placement.cov
        if not self._c.carry_through_ride or placed is None or P is None:
            return None
        if not main.initialized or main.reacquiring:
            return None
        T_floor_odom = floors.lift(main.T_map_odom, -floors.height_m)
        T_cab_floor = placed.inverse()
        cov = cov_compose(T_cab_floor, cov_inverse(placed, P), T_floor_odom,
                          _regular(main.covariance))  # fmt: skip
        return T_cab_floor @ T_floor_odom, _regular(cov)

    def alighted(
        self, stamp_ns: int, main: MapOdomFilter, cab: MapOdomFilter, floors: FloorFrame
    ) -> LandingSettle | None:
        """The doors opened: set ``main`` to the pose carried from the cab; the landing's
        settling (None: no cab placement or cab estimate yet, ``main`` left as it is)."""
        placed, P = self.placement.T_floor_cab, self.placement.cov
        if placed is None or P is None or not cab.initialized:
            return None
        T_cab_odom = cab.T_map_odom
        T_floor_odom = placed @ T_cab_odom
        cov = _regular(cov_compose(placed, P, T_cab_odom, _regular(cab.covariance)))
        main.initialize(stamp_ns, floors.lift(T_floor_odom), cov)
        self.anchored += 1
        logger.info("%d pose in map carried from the cab at the exit", stamp_ns)
        return LandingSettle(self._c, main.estimator.odometer_m, self._tags)
