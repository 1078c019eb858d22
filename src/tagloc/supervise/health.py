"""Per-input health: liveness (is it arriving, at what rate) and quality (are its fixes good).

Both are judged in stream time (message stamps), so a replayed bag and a live robot give the same
verdicts. Memory is constant: rates are exponential averages, quality a ring of the last
``window`` fixes.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from enum import StrEnum

from tagloc.units import S_NS

__all__ = ["FixQualityMonitor", "InputHealth", "Liveness", "QualityState", "QualityVerdict"]

_EMA = 0.05  # weight of the newest interval in the rate estimate


@dataclass(frozen=True, slots=True)
class InputHealth:
    """One input's liveness at a stamp (in the status message).

    Attributes
    ----------
    alive : bool
        A message arrived within ``timeout_s`` (False before the first).
    age_s : float
        Since the last message (``inf`` before the first).
    rate_hz, expected_rate_hz : float
        Measured (exponential average of the intervals) and nominal rate.
    gaps : int
        Silences longer than the timeout so far.
    count : int
        Messages so far.
    """

    alive: bool
    age_s: float
    rate_hz: float
    expected_rate_hz: float
    gaps: int
    count: int


class Liveness:
    """Arrival times of one input (odometry, camera, scanner)."""

    def __init__(self, timeout_s: float, expected_rate_hz: float) -> None:
        self.timeout_ns = round(timeout_s * S_NS)
        self.expected_rate_hz = expected_rate_hz
        self.last_ns: int | None = None
        self._dt_s = 1.0 / expected_rate_hz
        self.gaps = 0
        self.count = 0

    def arrived(self, stamp_ns: int) -> None:
        """A message stamped ``stamp_ns`` (an older or repeated stamp counts, never rewinds)."""
        self.count += 1
        if self.last_ns is not None:
            dt = stamp_ns - self.last_ns
            if dt <= 0:
                return
            if dt > self.timeout_ns:
                self.gaps += 1
            else:
                self._dt_s += _EMA * (dt / S_NS - self._dt_s)
        self.last_ns = stamp_ns

    def restart(self) -> None:
        """Forget the last arrival (the clock jumped back); counts are kept."""
        self.last_ns = None

    def alive(self, now_ns: int) -> bool:
        """Whether a message arrived within the timeout before ``now_ns``."""
        return self.last_ns is not None and now_ns - self.last_ns <= self.timeout_ns

    def report(self, now_ns: int) -> InputHealth:
        age = math.inf if self.last_ns is None else max(now_ns - self.last_ns, 0) / S_NS
        rate = 0.0 if self.last_ns is None else 1.0 / self._dt_s
        return InputHealth(
            self.alive(now_ns), age, rate, self.expected_rate_hz, self.gaps, self.count
        )


class QualityState(StrEnum):
    """A fix source's quality verdict."""

    HEALTHY = "healthy"
    DEGRADED = "degraded"


@dataclass(frozen=True, slots=True)
class QualityVerdict:
    """A source's quality over its last fixes (in the status message).

    Attributes
    ----------
    state : QualityState
    offered, accepted : int
        Fixes in the window, and how many the filter applied.
    acceptance : float
        ``accepted / offered`` (NaN with none).
    mean_nis : float
        Mean normalized innovation squared per degree of freedom of the window's fixes that
        were tested (about 1 for an honest covariance; NaN with none).
    mean_reproj_px : float
        Mean RMS reprojection error of the window's fixes (NaN when the source has none).
    reason : str
        Why it is degraded ('' when healthy).
    """

    state: QualityState
    offered: int
    accepted: int
    acceptance: float
    mean_nis: float
    mean_reproj_px: float
    reason: str


class FixQualityMonitor:
    """Quality of one fix source over its last ``window`` fixes, with hysteresis.

    Degraded once acceptance < ``enter_acceptance``, mean NIS > ``enter_nis`` or mean
    reprojection error > ``enter_reproj_px`` (with at least ``window // 2`` fixes in the window);
    healthy again only when all are back past the exit limits.
    """

    def __init__(
        self, window: int, enter_acceptance: float, exit_acceptance: float, enter_nis: float,
        exit_nis: float, enter_reproj_px: float, exit_reproj_px: float,
    ) -> None:  # fmt: skip
        self._ring: deque[tuple[bool, float, float]] = deque(maxlen=window)
        self._min_n = max(window // 2, 1)
        self._enter = (enter_acceptance, enter_nis, enter_reproj_px)
        self._exit = (exit_acceptance, exit_nis, exit_reproj_px)
        self.state = QualityState.HEALTHY
        self.reason = ""

    def add(self, accepted: bool, nis_per_dof: float, reproj_px: float) -> None:
        """One fix offered to the filter (``nis_per_dof``, ``reproj_px``: NaN if unknown)."""
        self._ring.append((accepted, nis_per_dof, reproj_px))
        self._judge()

    def clear(self) -> None:
        """Forget the window (after the input died: its old fixes say nothing now)."""
        self._ring.clear()
        self.state, self.reason = QualityState.HEALTHY, ""

    def _stats(self) -> tuple[int, int, float, float, float]:
        n = len(self._ring)
        acc = sum(a for a, _, _ in self._ring)
        nis = [v for _, v, _ in self._ring if math.isfinite(v)]
        rep = [v for _, _, v in self._ring if math.isfinite(v)]
        mean_nis = sum(nis) / len(nis) if nis else math.nan
        mean_rep = sum(rep) / len(rep) if rep else math.nan
        return n, acc, acc / n if n else math.nan, mean_nis, mean_rep

    def _judge(self) -> None:
        n, _, acceptance, nis, rep = self._stats()
        if n < self._min_n:
            return
        if self.state is QualityState.HEALTHY:
            a, s, r = self._enter
            why = [
                f"acceptance {acceptance:.2f} < {a:g}" if acceptance < a else "",
                f"mean NIS {nis:.1f} > {s:g}" if nis > s else "",
                f"mean reprojection {rep:.2f} px > {r:g}" if rep > r else "",
            ]
            if any(why):
                self.state = QualityState.DEGRADED
                self.reason = ", ".join(w for w in why if w) + f" over {n} fixes"
        else:
            a, s, r = self._exit
            ok_nis, ok_rep = not nis > s, not rep > r  # NaN (nothing tested) passes
            if acceptance >= a and ok_nis and ok_rep:
                self.state, self.reason = QualityState.HEALTHY, ""

    def verdict(self) -> QualityVerdict:
        n, acc, acceptance, nis, rep = self._stats()
        return QualityVerdict(self.state, n, acc, acceptance, nis, rep, self.reason)
