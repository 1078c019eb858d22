"""Localization: the ``map -> odom`` fusion filter, its gates and its event log; the fiducial
fix source (:class:`FiducialFixSource`), the streaming node (:class:`LocalizerNode`) and its one
driver (:func:`run`; :func:`record_run` into a :class:`LocalizationRun`).

The filter (:class:`MapOdomFilter`) estimates the correction ``T_map_odom`` from absolute fixes
(:class:`TagFix`: ``T_map_base`` at a stamp with a right-tangent covariance ``[x, y, z, rx, ry,
rz]``) and the odometry ``odom -> base`` in a :class:`~tagloc.frames.TransformBuffer`, and
publishes it so that the odometry chain never jumps. Every decision is a :class:`FilterEvent` in
its :class:`EventLog`. Tunables live in ``localizer.yaml`` (:class:`LocalizerConfig`).

It composes two parts, each usable alone: the estimator (:class:`MapOdomEstimator`: the state,
its covariance, the odometry path integral and the iterated EKF; ``predict``, ``innovation``,
``update``, ``update_partial``) and the fix policy (:class:`FixPolicy`: what the estimator is
given, and the capped publication; ``decide``, ``decide_partial``), with the suspect-source and
kidnap books of :class:`RecoveryBooks`. A fix as the estimator uses it is a :class:`Candidate`.

Policies (:class:`FixPolicy`)
    - No prior at start-up: the first ``k`` mutually consistent fixes initialize the state.
    - Chi-square gate on the innovation's Mahalanobis distance (dof 6, planar 3).
    - A fix with a high reprojection error is never used.
    - After a gap (no accepted fix for ``gap_s`` or ``gap_m``): ``k`` consistent fixes again.
    - The published correction jumps by at most a cap per update (remainder carried).
    - Kidnap: ``n`` gated fixes, mutually consistent, from ``min_sources`` sources, with no
      accepted fix among them, re-initialize the state (a lone glint cannot).
    - A source gated repeatedly while others are accepted (a moved tag) is flagged suspect and
      its fixes rejected.
"""

from tagloc.localize.candidate import Candidate
from tagloc.localize.config import LocalizerConfig, load_localizer_config, save_localizer_config
from tagloc.localize.driver import Clock, RunResult, StreamInputError, record_run, run
from tagloc.localize.estimator import MapOdomEstimator
from tagloc.localize.events import EventKind, EventLog, FilterEvent
from tagloc.localize.fiducial import FiducialConfig, FiducialFixSource, FrameFixes
from tagloc.localize.filter import MapOdomFilter
from tagloc.localize.fix import (
    CorrectionUpdate,
    FixQuality,
    LocalizeError,
    PartialFix,
    PoseWithCovariance,
    TagFix,
    planar_projection_jacobian,
)
from tagloc.localize.gating import (
    ConsistencyBuffer,
    CorrectionCap,
    QualityLimits,
    SourceMonitor,
    chi2_threshold,
)
from tagloc.localize.iekf import Innovation
from tagloc.localize.motion import CalibrationModel, PathMotion, ProcessNoise
from tagloc.localize.node import LocalizerNode
from tagloc.localize.odometry_path import OdometryPath
from tagloc.localize.policy import FixPolicy
from tagloc.localize.recovery import KidnapRule, RecoveryBooks, SuspectRule
from tagloc.localize.registry import available_fix_sources, register_fix_source
from tagloc.localize.run import CameraFrameRecord, FixAttempt, LocalizationRun
from tagloc.localize.sources import FixSource

__all__ = [
    "CalibrationModel",
    "CameraFrameRecord",
    "Candidate",
    "Clock",
    "ConsistencyBuffer",
    "CorrectionCap",
    "CorrectionUpdate",
    "EventKind",
    "EventLog",
    "FiducialConfig",
    "FiducialFixSource",
    "FilterEvent",
    "FixAttempt",
    "FixPolicy",
    "FixQuality",
    "FixSource",
    "FrameFixes",
    "Innovation",
    "KidnapRule",
    "LocalizationRun",
    "LocalizeError",
    "LocalizerConfig",
    "LocalizerNode",
    "MapOdomEstimator",
    "MapOdomFilter",
    "OdometryPath",
    "PartialFix",
    "PathMotion",
    "PoseWithCovariance",
    "ProcessNoise",
    "QualityLimits",
    "RecoveryBooks",
    "RunResult",
    "SourceMonitor",
    "StreamInputError",
    "SuspectRule",
    "TagFix",
    "available_fix_sources",
    "chi2_threshold",
    "load_localizer_config",
    "planar_projection_jacobian",
    "record_run",
    "register_fix_source",
    "run",
    "save_localizer_config",
]
