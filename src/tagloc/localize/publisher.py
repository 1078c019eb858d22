"""The published ``map -> odom``: the filter's estimate, moved toward at most the cap at a time.

Controllers never read this (they read ``odom -> base``); planners read ``map -> base`` through
it, so it must not jump. :class:`CorrectionPublisher` keeps the correction in force and its
history (:meth:`correction_at`), and bounds every change of the published ``map -> base`` at the
robot's pose (``T_map_odom @ T_odom_base``) by the cap (:class:`~tagloc.localize.gating.
CorrectionCap`), carrying the rest to later publications:

- per publication stamp (:meth:`publish`): the updates published at one stamp (the fixes of one
  frame, a batch applied after a gap, late fixes published at the latest stamp) share one cap;
- per odometry step (:meth:`end_step`, called by the filter's ``predict`` at every odometry
  sample): whatever was published since the previous step (updates, the calibrated drift) stays
  within the cap of what was in force then;
- per odometry step, with a speed limit (``max_speed_m_s``, ``max_rate_rad_s``): the step's
  change is also bounded by the limit times the step's duration, so a run of accepted fixes
  cannot walk the correction faster than a planner can follow;
- a snap, a declared (re)initialization, publishes the estimate as it is.

Every clipped publication is reported (``on_capped``) with which bound held it (``cap`` or
``speed limit``) and the remainder carried.

Publications never go back in time: one stamped before the latest is recorded at the latest.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

import numpy as np

from tagloc.geometry import SE2, SE3
from tagloc.localize.fix import CorrectionUpdate, LocalizeError
from tagloc.localize.gating import CorrectionCap, Pose

__all__ = ["CorrectionPublisher"]

#: ``on_capped(stamp_ns, detail)``: told of every clipped publication (the filter logs it).
CappedHook = Callable[[int, str], None]


class CorrectionPublisher:
    """The correction in force and its history (module docstring).

    Parameters
    ----------
    cap : CorrectionCap
    history_size : int
        Publications kept for :meth:`correction_at`.
    planar : bool
        Corrections are SE(2) (recorded as SE(3)).
    on_capped : callable
        Called with the stamp and a description of the remainder when a publication is clipped.
    """

    def __init__(
        self, cap: CorrectionCap, history_size: int, planar: bool, on_capped: CappedHook,
        speed: tuple[float, float] | None = None,
    ) -> None:  # fmt: skip
        self._cap, self._planar, self._on_capped = cap, planar, on_capped
        self._speed = speed  # (m/s, rad/s) or None
        self._step_stamp: int | None = None
        self._history: deque[CorrectionUpdate] = deque(maxlen=history_size)
        self.current: Pose | None = None  # in force now (may be ahead of the history: drift)
        self._cap_ref: Pose | None = None  # in force before the current publication stamp
        self._cap_stamp = -1
        self._step_ref: Pose | None = None  # in force at the end of the last odometry step
        self._appended: Pose | None = None  # the last one recorded in the history

    @property
    def history(self) -> tuple[CorrectionUpdate, ...]:
        """Published corrections (stamps non-decreasing), oldest first."""
        return tuple(self._history)

    def correction_at(self, stamp_ns: int) -> SE3:
        """The published ``T_map_odom`` in force at ``stamp_ns`` (the latest at or before it).

        Raises
        ------
        LocalizeError
            Before the first (kept) publication.
        """
        for correction in reversed(self._history):  # queries are mostly recent
            if correction.stamp_ns <= stamp_ns:
                return correction.T_map_odom
        first = f"the first is at {self._history[0].stamp_ns} ns" if self._history else "none yet"
        raise LocalizeError(f"no map -> odom correction at {stamp_ns} ns ({first})")

    def publish(self, X: Pose, stamp_ns: int, odom: SE3, *, snap: bool) -> None:
        """Publish the estimate ``X`` at ``stamp_ns``, clipped to the cap of this publication
        stamp unless ``snap`` (``odom``: ``T_odom_base`` where the jump is judged)."""
        last = self._history[-1].stamp_ns if self._history else stamp_ns
        stamp = max(stamp_ns, last)
        if self.current is not None and stamp != self._cap_stamp:
            self._cap_ref, self._cap_stamp = self.current, stamp  # in force before `stamp`
        new: Pose = X
        if snap:  # later publications at this stamp, and the odometry step, cap from here
            self._cap_ref, self._cap_stamp, self._step_ref = X, stamp, None
        elif self._cap_ref is not None:
            clipped = self._clip(self._cap_ref, X, stamp_ns, odom)
            new = X if clipped is None else clipped
        self._record(new, stamp)

    def drift(self, T_map_odom: Pose) -> None:
        """Move the correction in force without a publication (the calibrated odometry's drift;
        recorded by the next :meth:`publish` or :meth:`end_step`)."""
        self.current = T_map_odom

    def end_step(self, stamp_ns: int, odom: Callable[[], SE3]) -> None:
        """End an odometry step: clip what changed since the last step to the cap (judged at
        ``odom()``, ``T_odom_base`` at ``stamp_ns``, looked up only if needed) and record it."""
        last_step, self._step_stamp = self._step_stamp, stamp_ns
        if self.current is None:
            return
        if self._step_ref is not None and self._step_ref is not self.current:
            cap, label = self._cap, "cap"
            if self._speed is not None and last_step is not None:
                dt = max(stamp_ns - last_step, 0) / 1e9
                v_t, v_r = self._speed[0] * dt, self._speed[1] * dt
                if v_t < cap.max_translation_m or v_r < cap.max_rotation_rad:
                    cap = CorrectionCap(
                        min(v_t, cap.max_translation_m), min(v_r, cap.max_rotation_rad)
                    )
                    label = "speed limit"
            clipped = self._clip(self._step_ref, self.current, stamp_ns, odom(), cap, label)
            if clipped is not None:
                self.current = clipped
        if self.current is not self._appended:  # drifted or clipped since recorded
            self._record(self.current, stamp_ns)
        self._step_ref = self.current

    def _record(self, T_map_odom: Pose, stamp_ns: int) -> None:
        self.current = self._appended = T_map_odom
        last = self._history[-1].stamp_ns if self._history else stamp_ns
        T = T_map_odom.to_se3() if isinstance(T_map_odom, SE2) else T_map_odom
        self._history.append(CorrectionUpdate(max(stamp_ns, last), T))

    def _clip(
        self, ref: Pose, target: Pose, stamp_ns: int, odom: SE3,
        cap: CorrectionCap | None = None, label: str = "cap",
    ) -> Pose | None:  # fmt: skip
        """``target`` moved back to within the cap of ``ref``, both seen at the robot's pose
        ``odom``, or None if it is within already (the remainder is reported, and carried)."""
        A = SE2.from_se3(odom) if self._planar else odom
        X_A = target @ A  # type: ignore[operator]
        jump = (ref @ A).inverse() @ X_A  # type: ignore[operator]
        step, clipped = (cap or self._cap).clip(jump)
        if not clipped:
            return None
        # new @ A = ref @ A @ step, built from the target (no round-off build-up)
        rest = step.inverse() @ jump  # type: ignore[operator]
        angle = float(np.linalg.norm(rest.log()[2 if self._planar else 3 :]))
        self._on_capped(
            stamp_ns,
            f"{label}: remainder {np.linalg.norm(rest.translation):.3f} m, "
            f"{math.degrees(angle):.2f} deg",
        )
        out: Pose = X_A @ rest.inverse() @ A.inverse()  # type: ignore[operator]
        if isinstance(out, SE3):  # the products carry the last clipped publication: project
            out = SE3(rotation=out.rotation.normalized(), translation=out.translation)
        return out
