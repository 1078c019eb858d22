"""``localizer.yaml``: ``supervisor``: source health, the degradation ladder and the status.

Units: seconds, hertz, pixels. Every field has a default; see :mod:`tagloc.supervise` for what
each level means and changes.
"""

from __future__ import annotations

from pydantic import Field, model_validator

from tagloc.config import FieldPathError, StrictModel

__all__ = ["HealthConfig", "LadderConfig", "SupervisorConfig"]


class HealthConfig(StrictModel):
    """Liveness and quality limits of one input."""

    #: No message for this long (s) and the input is dead (a camera unplugged, a stalled
    #: odometry). The ladder leaves any level that needs it on the first odometry sample after.
    timeout_s: float = Field(1.0, gt=0, le=3600)
    #: The input's nominal rate (Hz); the status reports the measured one beside it.
    expected_rate_hz: float = Field(30.0, gt=0, le=10_000)

    @model_validator(mode="after")
    def _timeout_above_period(self) -> HealthConfig:
        if not self.timeout_s > 1.0 / self.expected_rate_hz:
            raise FieldPathError(
                ("timeout_s",),
                f"must be above the period of expected_rate_hz ({1.0 / self.expected_rate_hz:g} s)",
            )
        return self


class LadderConfig(StrictModel):
    """Thresholds of the ladder: enter (worse) and exit (better) differ, plus a dwell time.

    Quality is judged over the last ``window`` fixes of a source offered to the filter:
    the source is *degraded* once its acceptance rate falls below ``enter_acceptance`` or its
    mean normalized innovation squared (NIS, per degree of freedom) rises above ``enter_nis``,
    and *healthy* again only once they are back past ``exit_acceptance`` / ``exit_nis``.
    A quality change moves the ladder only ``min_dwell_s`` after its last transition; a dead
    input or a lost estimate moves it at once (hard reasons, never delayed).
    """

    window: int = Field(20, ge=2, le=10_000)
    enter_acceptance: float = Field(0.2, ge=0, le=1)
    exit_acceptance: float = Field(0.5, ge=0, le=1)
    enter_nis: float = Field(6.0, gt=0, le=1e6)
    exit_nis: float = Field(3.0, gt=0, le=1e6)
    #: Mean RMS reprojection error (px) of the window's fixes that marks a source degraded.
    enter_reproj_px: float = Field(1.5, gt=0, le=1e4)
    exit_reproj_px: float = Field(1.0, gt=0, le=1e4)
    min_dwell_s: float = Field(30.0, ge=0, le=3600)

    @model_validator(mode="after")
    def _hysteresis(self) -> LadderConfig:
        if self.exit_acceptance < self.enter_acceptance:
            raise ValueError("exit_acceptance must be >= enter_acceptance (hysteresis)")
        if self.exit_nis > self.enter_nis:
            raise ValueError("exit_nis must be <= enter_nis (hysteresis)")
        if self.exit_reproj_px > self.enter_reproj_px:
            raise ValueError("exit_reproj_px must be <= enter_reproj_px (hysteresis)")
        return self


class SupervisorConfig(StrictModel):
    """The supervisor: per-input health, the ladder, the status message's rate."""

    #: Status messages per second of stream time (at odometry stamps).
    status_rate_hz: float = Field(1.0, gt=0, le=100)
    odometry: HealthConfig = HealthConfig(timeout_s=0.5, expected_rate_hz=100.0)
    camera: HealthConfig = HealthConfig(timeout_s=1.0, expected_rate_hz=30.0)
    #: The lidar's sweeps (a lidar fix source's input).
    lidar: HealthConfig = HealthConfig(timeout_s=0.5, expected_rate_hz=10.0)
    ladder: LadderConfig = LadderConfig()
    #: Odometry stamped more than this (s) before the previous sample is a clock jumped back:
    #: the node starts over (smaller steps back are skipped and counted).
    clock_jump_s: float = Field(1.0, gt=0, le=3600)
