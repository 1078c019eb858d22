"""``localizer.yaml``: the tunables of the ``map -> odom`` filter, with documented defaults.

Loaded like every tagloc file (:mod:`tagloc.config`): unknown keys, NaN and wrong types are one
:class:`~tagloc.errors.ConfigError` line naming the file and the field path, e.g.
``localizer.yaml: gates.chi2_quantile: input should be less than 1``. Every section may be left
out (its defaults apply). The algorithms never see this model: :meth:`MapOdomFilter.from_config
<tagloc.localize.filter.MapOdomFilter.from_config>` unpacks it into plain arguments.

Units: metres, radians, seconds (converted to integer nanoseconds by the factory); the one angle
humans type, the per-update cap, is in degrees as its name says.
"""

from __future__ import annotations

import os
from typing import Annotated, Literal

import yaml
from pydantic import Field

from tagloc.config import StrictModel, parse_yaml_mapping, read_text_file, validate
from tagloc.fileutil import atomic_write_text

_Sigma = Annotated[float, Field(ge=0, le=1e3)]
#: Standard deviations per axis ``[x, y, z, rx, ry, rz]``, each ``>= 0``.
SigmaVec6 = tuple[_Sigma, _Sigma, _Sigma, _Sigma, _Sigma, _Sigma]


class FramesConfig(StrictModel):
    """Frame names (configuration, never literals in the algorithm)."""

    map_frame: str = Field("map", min_length=1, max_length=200)
    odom_frame: str = Field("odom", min_length=1, max_length=200)
    base_frame: str = Field("base_link", min_length=1, max_length=200)


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


class GatesConfig(StrictModel):
    """Per-fix gates and the k-consistency rule."""

    #: Chi-square quantile of the Mahalanobis gate (dof 6, or 3 in planar mode): a consistent
    #: fix is wrongly gated once in 1 / (1 - q) fixes.
    chi2_quantile: float = Field(0.999, gt=0, lt=1)
    #: A fix whose own RMS reprojection error exceeds this is never used (a glint, blur, a bad
    #: corner): good AprilTag corners are at 0.1-0.5 px.
    max_reproj_err_px: float = Field(2.0, gt=0, le=1e6)
    #: IPPE ambiguity ratio above which a fix is refused (None: no limit; the chi-square gate
    #: already refuses a flipped branch once the state is known).
    max_ambiguity_ratio: float | None = Field(None, gt=0, le=1e6)
    #: Camera-to-tag range above which a fix is refused (None: no limit).
    max_range_m: float | None = Field(None, gt=0, le=1e6)
    #: Mutually consistent fixes required at start-up and after a gap before any is applied.
    k_consistent: int = Field(3, ge=1, le=100_000)
    #: The k fixes must lie within this window.
    consistency_window_s: float = Field(3.0, gt=0, le=1e6)
    #: A gap (re-acquisition needs k consistent fixes again): no accepted fix for this long ...
    gap_s: float = Field(10.0, gt=0, le=1e6)
    #: ... or over this much travel.
    gap_m: float = Field(5.0, gt=0, le=1e6)


class CapConfig(StrictModel):
    """Largest jump of the published ``map -> base`` (at the robot's pose) per update."""

    max_translation_m: float = Field(0.25, gt=0, le=1e6)
    max_rotation_deg: float = Field(5.0, gt=0, le=180)
    #: Publish the new correction at once on (re)initialization (a declared re-localization)
    #: instead of walking to it at the capped rate.
    snap_on_initialize: bool = True


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
    #: and pitch are ignored). For ground robots whose fixes are poor in those axes.
    planar: bool = False
    #: Iterated EKF: relinearize while the step seen at the base, ``|H dx|``, exceeds
    #: ``relinearize_tol`` (m or rad). Skipping it errs by about ``|H dx| |nu| / 2``: under
    #: 1-2 mm for steps below 5 cm, far under fix noise; larger steps (start-up, after a gap or
    #: a kidnap, a poor prior) iterate.
    max_iterations: int = Field(3, ge=1, le=20)
    relinearize_tol: float = Field(0.05, gt=0, le=1e6)
    #: Published corrections kept for ``correction_at``.
    history_size: int = Field(10_000, ge=1, le=10_000_000)
    #: Events kept in the event log (counts are always exact).
    max_events: int = Field(100_000, ge=1, le=10_000_000)


class LocalizerConfig(StrictModel):
    """Everything ``localizer.yaml`` holds; each section has documented defaults."""

    version: Literal[1] = 1
    frames: FramesConfig = FramesConfig()
    process_noise: ProcessNoiseConfig = ProcessNoiseConfig()
    calibration: CalibrationConfig = CalibrationConfig()
    gates: GatesConfig = GatesConfig()
    cap: CapConfig = CapConfig()
    kidnap: KidnapConfig = KidnapConfig()
    suspect: SuspectConfig = SuspectConfig()
    filter: FilterConfig = FilterConfig()

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
