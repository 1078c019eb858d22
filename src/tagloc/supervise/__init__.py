"""Supervision: per-input health, the degradation ladder, the status message.

:class:`Supervisor` judges, in stream time, whether each input is alive (liveness: rate and
timeout) and each fix source is good (quality: acceptance rate, normalized innovation,
reprojection error, with enter/exit hysteresis), and walks the degradation ladder
(:mod:`tagloc.supervise.ladder`: 1 lidar nominal, 2 markers carry, 3 markers alone, 4 odometry
only). Thresholds live in ``localizer.yaml``'s ``supervisor`` section
(:class:`SupervisorConfig`). In buildings with elevators it owns the map <-> cab handoff
(:mod:`tagloc.supervise.cab`, section ``elevators``: :class:`ElevatorConfig`) and the floor
(:mod:`tagloc.supervise.floors`). The streaming node in :mod:`tagloc.localize` feeds it.
"""

from tagloc.supervise.cab import CabHandoff, CabState, CabTransition, ElevatorConfig
from tagloc.supervise.config import HealthConfig, LadderConfig, SupervisorConfig
from tagloc.supervise.floors import FloorBook, FloorChange
from tagloc.supervise.health import (
    FixQualityMonitor,
    InputHealth,
    Liveness,
    QualityState,
    QualityVerdict,
)
from tagloc.supervise.ladder import Ladder, LadderTransition, Level
from tagloc.supervise.supervisor import EstimatorState, FixSourceSpec, StatusReport, Supervisor

__all__ = [
    "CabHandoff",
    "CabState",
    "CabTransition",
    "ElevatorConfig",
    "EstimatorState",
    "FixQualityMonitor",
    "FixSourceSpec",
    "FloorBook",
    "FloorChange",
    "HealthConfig",
    "InputHealth",
    "Ladder",
    "LadderConfig",
    "LadderTransition",
    "Level",
    "Liveness",
    "QualityState",
    "QualityVerdict",
    "StatusReport",
    "Supervisor",
    "SupervisorConfig",
]  # fmt: skip
