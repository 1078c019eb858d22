"""The degradation ladder: which absolute source carries the ``map -> odom`` correction now.

=====  ====================  =========================================================
level  name                  holds when
=====  ====================  =========================================================
1      ``lidar_nominal``     a lidar fix source is alive and healthy (plus level 4's
                             conditions below are *not* the case)
2      ``markers_carry``     a lidar source is alive but degraded; markers carry
3      ``markers_alone``     markers carry, no usable lidar (none, or dead)
4      ``odometry_only``     nothing absolute carries: the estimate is dead reckoning
=====  ====================  =========================================================

"Markers carry" means: the camera is alive, the tag source's quality is healthy, the estimate
exists and is not re-acquiring, and a fix was accepted within the gap (``gates.gap_s`` seconds
and ``gates.gap_m`` metres). Odometry alive is required by every level but 4.

What each level changes: levels 1-3 publish the fused correction as usual. At level 4 the
correction is held (it still follows the calibrated odometry), its covariance grows with the
distance travelled (the process noise), and the status says ``stale: true`` so that a planner
can slow down or stop; the filter keeps testing every fix that arrives.

Transitions (:class:`Ladder`): the target is the best level whose conditions hold. A move for a
*hard* reason (an input dead, the estimate lost or stale) happens at once; a move caused only by
a quality verdict (which has its own enter/exit hysteresis) waits ``min_dwell_s`` after the
previous transition, and so does a move up after a quality-driven move down. Every transition
carries its reason, naming why each level it left or skipped is unavailable.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from tagloc.units import S_NS

__all__ = ["Ladder", "LadderTransition", "Level"]



class Level(IntEnum):
    """Ladder levels, best first (module docstring)."""

    LIDAR_NOMINAL = 1
    MARKERS_CARRY = 2
    MARKERS_ALONE = 3
    ODOMETRY_ONLY = 4

    @property
    def label(self) -> str:
        return self.name.lower()


@dataclass(frozen=True, slots=True)
class LadderTransition:
    """One move of the ladder (an event of kind ``ladder``)."""

    stamp_ns: int
    from_level: Level
    to_level: Level
    reason: str
    hard: bool

    def to_dict(self) -> dict[str, object]:
        return {
            "stamp_ns": self.stamp_ns, "kind": "ladder", "from": int(self.from_level),
            "to": int(self.to_level), "from_name": self.from_level.label,
            "to_name": self.to_level.label, "reason": self.reason, "hard": self.hard,
        }  # fmt: skip


class Ladder:
    """The current level, its dwell time and the time spent at each level.

    Parameters
    ----------
    min_dwell_s : float
        Quality-driven moves wait this long after the previous transition.
    start : Level
        Level before anything is known (default ``ODOMETRY_ONLY``).
    """

    def __init__(self, min_dwell_s: float, start: Level = Level.ODOMETRY_ONLY) -> None:
        self.level = start
        self._dwell_ns = round(min_dwell_s * S_NS)
        self._since_ns: int | None = None  # stamp of the last transition (or the first step)
        self._last_hard = True
        self._clock_ns: int | None = None
        self.time_ns = {level: 0 for level in Level}
        self.transitions = 0

    def step(
        self, stamp_ns: int, unmet: dict[Level, list[str]], hard_unmet: dict[Level, list[str]]
    ) -> LadderTransition | None:
        """Advance to ``stamp_ns`` given, per level 1-3, why it is unavailable (``unmet``:
        all reasons; ``hard_unmet``: the hard ones only; empty lists: available)."""
        if self._clock_ns is not None and stamp_ns > self._clock_ns:
            self.time_ns[self.level] += stamp_ns - self._clock_ns
        self._clock_ns = stamp_ns if self._clock_ns is None else max(self._clock_ns, stamp_ns)
        if self._since_ns is None:
            self._since_ns = stamp_ns
        target = _best(unmet)
        if target == self.level:
            return None
        hard_target = _best(hard_unmet)
        dwelt = stamp_ns - self._since_ns >= self._dwell_ns
        if target > self.level:  # worse
            hard = hard_target >= target
            if not (hard or dwelt):
                return None
            left = range(self.level, target)
            reason = "; ".join(f"{Level(v).label}: {', '.join(unmet[Level(v)])}" for v in left)
        else:  # better: at once after a hard fall, else after the dwell
            hard = self._last_hard
            if not (hard or dwelt):
                return None
            skipped = [
                f"{Level(v).label}: {', '.join(unmet[Level(v)])}" for v in range(1, target)
            ]
            reason = f"{target.label} available" + (
                f" ({'; '.join(skipped)})" if skipped else ""
            )
        move = LadderTransition(stamp_ns, self.level, target, reason, hard)
        self.level, self._since_ns, self._last_hard = target, stamp_ns, hard
        self.transitions += 1
        return move

    def restart(self, stamp_ns: int) -> None:
        """The clock jumped back to ``stamp_ns``: time is counted from there on."""
        self._clock_ns = stamp_ns
        self._since_ns = stamp_ns

    def seconds_at_levels(self) -> dict[str, float]:
        """Stream time spent at each level so far, s (by level name)."""
        return {level.label: ns / S_NS for level, ns in self.time_ns.items()}


def _best(unmet: dict[Level, list[str]]) -> Level:
    for level in (Level.LIDAR_NOMINAL, Level.MARKERS_CARRY, Level.MARKERS_ALONE):
        if not unmet.get(level):
            return level
    return Level.ODOMETRY_ONLY
