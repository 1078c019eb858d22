"""``localizer.yaml``: the one configuration of the localizer node, with documented defaults.

Sections: ``frames`` (names, the published edge), ``tags`` (detector, PnP mode, pixel noise, how
fixes are formed), ``gates`` (one set for observations and fixes), ``process_noise``,
``calibration``, ``cap`` (per-update cap and speed limit), ``kidnap``, ``suspect``, ``filter``,
``supervisor`` (health, ladder, status rate), ``output`` (publication rate), ``lidar`` (the
scan-to-premap fix source, :mod:`tagloc.localize.config_lidar`) and ``elevators`` (the cab
frames, the map <-> cab handoff and floors, :class:`~tagloc.supervise.ElevatorConfig`). The resolved
configuration (every default written out) is saved with every run.

Loaded like every tagloc file (:mod:`tagloc.config`): unknown keys, NaN and wrong types are one
:class:`~tagloc.errors.ConfigError` line naming the file and the field path, e.g.
``localizer.yaml: gates.chi2_quantile: input should be less than 1``. Every section may be left
out (its defaults apply). The algorithms never see this model: :meth:`MapOdomFilter.from_config
<tagloc.localize.filter.MapOdomFilter.from_config>` hands its sections to the estimator's and
the fix policy's ``from_config``, which unpack them into plain arguments.

Units: metres, radians, seconds (converted to integer nanoseconds by the factory); the one angle
humans type, the per-update cap, is in degrees as its name says.
"""

from __future__ import annotations

import os
from typing import Annotated, Literal

import yaml
from pydantic import Field, model_validator

from tagloc.config import (
    FieldPathError,
    StrictModel,
    parse_yaml_mapping,
    read_text_file,
    validate,
)
from tagloc.fileutil import atomic_write_text
from tagloc.frames import OdometryFrameConfig
from tagloc.localize.config_lidar import LidarConfig
from tagloc.localize.config_tags import FramesConfig, GatesConfig, TagSensorConfig
from tagloc.supervise import ElevatorConfig, SupervisorConfig

_Sigma = Annotated[float, Field(ge=0, le=1e3)]
#: Standard deviations per axis ``[x, y, z, rx, ry, rz]``, each ``>= 0``.
SigmaVec6 = tuple[_Sigma, _Sigma, _Sigma, _Sigma, _Sigma, _Sigma]


class ProcessNoiseConfig(StrictModel):
    """Random walk of ``T_map_odom`` driven by the odometry's motion (drift is per metre).

    Each is the standard deviation, per axis ``[x, y, z, rx, ry, rz]`` of the base frame, of the
    odometry error accumulated over one metre of travel, one radian of rotation, one second:
    variances add linearly with distance, rotation and time (a random walk). The defaults suit a
    legged robot's kinematic odometry (several % of distance, yaw the worst axis).
    """

    sigma_per_sqrt_m: SigmaVec6 = (0.05, 0.05, 0.02, 0.005, 0.005, 0.02)
    sigma_per_sqrt_rad: SigmaVec6 = (0.02, 0.02, 0.005, 0.005, 0.005, 0.03)
    #: Small time term: keeps the covariance from collapsing while the robot stands still.
    sigma_per_sqrt_s: SigmaVec6 = (0.002, 0.002, 0.002, 0.001, 0.001, 0.001)
    #: Resolution of the odometry path integral (path length and the frame of the noise); finer
    #: than 5 ms is finer than any odometry and only costs time.
    motion_step_s: float = Field(0.1, ge=0.005, le=10.0)
    #: The odometry message's own pose covariance: ``ignore`` it (default: drivers often publish
    #: a constant), or add its ``growth`` between consecutive messages (the positive part of
    #: ``cov_k - cov_{k-1}``, in the odometry frame, ROS order ``[x, y, z, rx, ry, rz]``) to the
    #: correction's covariance, on top of the per-metre walk above (set that low when the
    #: odometry's covariance is calibrated, e.g. from a VIO or a fused legged estimator).
    odometry_covariance: Literal["ignore", "growth"] = "ignore"


class CalibrationConfig(StrictModel):
    """Online odometry calibration: the systematic part of the drift, estimated with the state.

    The filter estimates four corrections of the odometry's increments (see
    :mod:`tagloc.localize.motion`): ``scale`` (fraction of distance), ``lateral`` (sideways m per
    m), ``yaw_per_m`` (yaw bias, deg per m) and ``yaw_scale`` (fraction of the angle turned), each
    the value to *add* (an odometry over-reading distance by 4 % calibrates to ``scale = -0.04``).
    Between fixes the correction then drifts as the calibrated odometry says, instead of standing
    still while the odometry drifts away. Order of every vector: scale, lateral, yaw_per_m (deg),
    yaw_scale.
    """

    enabled: bool = True
    #: 1-sigma of each parameter before any fix (mean 0).
    prior_sigma: tuple[_Sigma, _Sigma, _Sigma, _Sigma] = (0.05, 0.02, 0.2, 0.03)
    #: Random walk of each parameter per sqrt(m) travelled (they change with floor and gait).
    sigma_per_sqrt_m: tuple[_Sigma, _Sigma, _Sigma, _Sigma] = (0.001, 0.0005, 0.005, 0.0005)
    #: Estimates are clamped to +- these (a plausible odometry).
    max_abs: tuple[_Sigma, _Sigma, _Sigma, _Sigma] = (0.2, 0.1, 2.0, 0.2)


class CapConfig(StrictModel):
    """Largest jump of the published ``map -> base`` (at the robot's pose) per update."""

    max_translation_m: float = Field(0.25, gt=0, le=1e6)
    max_rotation_deg: float = Field(5.0, gt=0, le=180)
    #: Publish the new correction at once on (re)initialization (a declared re-localization)
    #: instead of walking to it at the capped rate.
    snap_on_initialize: bool = True
    #: Speed limit of the published correction at the robot's pose, m/s and deg/s (beside the
    #: per-update cap: a stream of accepted fixes cannot walk the correction faster than this;
    #: the remainder is carried). None: no limit.
    max_speed_m_s: float | None = Field(None, gt=0, le=1e3)
    max_rate_deg_s: float | None = Field(None, gt=0, le=1e5)


class OutputConfig(StrictModel):
    """What the node publishes and how often (stream time)."""

    #: ``map -> odom`` transform and pose-with-covariance messages per second (0: at every
    #: odometry sample).
    publish_rate_hz: float = Field(10.0, ge=0, le=1000)
    #: Publish each odometry sample's estimate before applying the camera frames that sample
    #: completes (their fixes then enter as fixes just older than the state, and show at the
    #: next sample): the odometry -> transform latency no longer includes PnP and the filter
    #: update. Off for replays (results identical to earlier runs); ``--realtime`` turns it on.
    publish_first: bool = False


class KidnapConfig(StrictModel):
    """Re-initialize when the filter is consistently surprised (see ``tagloc.localize``)."""

    enabled: bool = True
    #: Gated fixes, mutually consistent, with no accepted fix between them, that re-initialize.
    n_fixes: int = Field(4, ge=2, le=100_000)
    #: Distinct sources among them: one tag alone cannot tell a kidnap from a moved tag.
    min_sources: int = Field(2, ge=1, le=100_000)
    #: The n fixes must lie within this window.
    window_s: float = Field(5.0, gt=0, le=1e6)
    #: Or this many such fixes of a single source (0: never from one tag alone), each putting
    #: the robot at least ``one_source_min_jump_m`` from where the filter thinks it is. After a
    #: kidnap often one tag is in view: one tag seen for half a second (15 frames at 30 Hz)
    #: re-localizes. The distance rule keeps a tag moved since the survey (by less than that)
    #: from re-localizing the robot when seen alone; seen with other tags it is flagged suspect
    #: after ``suspect.min_gated`` fixes, long before this.
    n_fixes_one_source: int = Field(15, ge=0, le=100_000)
    one_source_min_jump_m: float = Field(1.0, ge=0, le=1e6)

    @model_validator(mode="after")
    def _sources_within_fixes(self) -> KidnapConfig:
        if self.min_sources > self.n_fixes:  # n fixes could never come from that many sources
            raise FieldPathError(("min_sources",), "must be at most n_fixes")
        return self


class SuspectConfig(StrictModel):
    """Flag a source (a moved tag) whose fixes are gated while other sources are accepted."""

    #: Consecutive gated fixes of the source, with another source accepted meanwhile.
    min_gated: int = Field(3, ge=1, le=100_000)
    #: Consecutive fixes of a suspect source that pass the gate (not applied) to clear it.
    clear_after: int = Field(10, ge=1, le=100_000)
    #: Consecutive gated fixes count as "wrong the same way" only if the corrections they imply
    #: agree within this (m, and deg below): a moved tag repeats its pose to centimetres, while
    #: glints decoded under its id are vague (metres of covariance) and pass a chi-square pair
    #: test for that reason alone. Two gated fixes are compared only if they are at most
    #: ``kidnap.window_s`` apart (the same window the kidnap test uses).
    max_spread_m: float = Field(0.3, gt=0, le=1e6)
    max_spread_deg: float = Field(5.0, gt=0, le=180)


class FilterConfig(StrictModel):
    """The estimator itself."""

    #: Estimate only x, y, yaw of ``T_map_odom`` (z, roll, pitch pinned at 0; the fixes' z, roll
    #: and pitch are ignored). For ground robots whose fixes are poor in those axes; the odometry's
    #: z is then the base's height above the floor the odometry started on.
    planar: bool = False
    #: Iterated EKF: relinearize while the step seen at the base, ``|H dx|``, exceeds
    #: ``relinearize_tol`` (m or rad). Skipping it errs by about ``|H dx| |nu| / 2``: under
    #: 1-2 mm for steps below 5 cm, far under fix noise; larger steps (start-up, after a gap or
    #: a kidnap, a poor prior) iterate.
    max_iterations: int = Field(3, ge=1, le=20)
    relinearize_tol: float = Field(0.05, gt=0, le=1e6)
    #: Published corrections kept for ``correction_at`` (a new one at each fix and each drift
    #: step: 1000 are 30-60 s of driving; the node itself asks only for the newest).
    history_size: int = Field(1000, ge=1, le=10_000_000)
    #: Events kept in the filter's log for inspection (counts are always exact; every event
    #: also streams to the node's sinks as it happens).
    max_events: int = Field(1000, ge=1, le=10_000_000)


class LocalizerConfig(StrictModel):
    """Everything ``localizer.yaml`` holds; each section has documented defaults."""

    version: Literal[1] = 1
    frames: FramesConfig = FramesConfig()
    odometry_frame: OdometryFrameConfig = OdometryFrameConfig()
    process_noise: ProcessNoiseConfig = ProcessNoiseConfig()
    calibration: CalibrationConfig = CalibrationConfig()
    gates: GatesConfig = GatesConfig()
    cap: CapConfig = CapConfig()
    kidnap: KidnapConfig = KidnapConfig()
    suspect: SuspectConfig = SuspectConfig()
    filter: FilterConfig = FilterConfig()
    tags: TagSensorConfig = TagSensorConfig()
    supervisor: SupervisorConfig = SupervisorConfig()
    output: OutputConfig = OutputConfig()
    lidar: LidarConfig = LidarConfig()
    elevators: ElevatorConfig = ElevatorConfig()

    @classmethod
    def from_yaml_text(cls, text: str, source: str = "<string>") -> LocalizerConfig:
        """Parse and validate YAML text; ``source`` names it in errors.

        Raises
        ------
        ConfigError
            One line: ``source: field.path: problem``.
        """
        return validate(cls, parse_yaml_mapping(text, source), source)

    def to_yaml_text(self) -> str:
        """This configuration as YAML (every default written out)."""
        return yaml.safe_dump(self.model_dump(mode="json"), sort_keys=False)


def load_localizer_config(path: str | os.PathLike[str]) -> LocalizerConfig:
    """Read and validate ``localizer.yaml``. Raises ``ConfigError`` (one line) on any problem."""
    text = read_text_file(path, "localizer config")
    return LocalizerConfig.from_yaml_text(text, source=os.fspath(path))


def save_localizer_config(config: LocalizerConfig, path: str | os.PathLike[str]) -> None:
    """Write ``config`` as YAML to ``path`` atomically (beside a result, to reproduce it)."""
    atomic_write_text(path, config.to_yaml_text())
